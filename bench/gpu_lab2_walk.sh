#!/usr/bin/env bash
# Lab 2's sync-free torch walk on a CUDA machine, in one go: the tests of its CUDA-graph
# path (cached graphs against the eager walk), the headline bench rows (LBVH build; bunny,
# 1M primary rays: eager, compiled, compiled + CUDA graphs) and a profile of one warm
# traversal. Needs python3, torch, triton, numpy, matplotlib, pytest (trimesh from .whl/
# when present).
#
#   OUT=bench/results/nvidia-h200/lab2_walk bash bench/gpu_lab2_walk.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/lab2_walk}"
mkdir -p "$OUT"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
{
    nvidia-smi -L
    python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__)"
} > "$OUT/device.txt" 2>&1
timeout "${TEST_TIMEOUT:-150}" python3 -m pytest -q -p no:cacheprovider \
    tests/meta/test_lab2_graph_cache.py tests/meta/test_lab2_compiled.py > "$OUT/tests_cuda.log" 2>&1
echo "tests: exit $?" >> "$OUT/tests_cuda.log"
timeout "${BENCH_TIMEOUT:-170}" python3 bench/lab2_accel.py --device cuda --headline \
    --out "$OUT" > "$OUT/bench.log" 2>&1
echo "bench: exit $?" >> "$OUT/bench.log"
timeout "${PROFILE_TIMEOUT:-40}" python3 bench/lab2_profile.py --check-every 32 --out "$OUT" \
    > /dev/null 2> "$OUT/profile.err"
echo "profile: exit $?" >> "$OUT/profile.err"
