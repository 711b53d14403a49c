#!/usr/bin/env bash
# The Lab 3 tracers and the Lab 4 frame on a CUDA machine, in one go: the tests of every
# GPU kernel they use (compiled), then bench/lab3_gpu.py and the frame series of
# bench/lab4_march.py. Needs python3 with torch, triton, numpy, matplotlib, pytest and nvcc;
# trimesh from wheels in .whl/ when it is not installed.
#
#   OUT=/some/dir bash bench/gpu_tracers.sh
#
# Writes tests_cuda.log, lab3_gpu/ (bench.log, lab3_gpu.json/.md, ray_sets.json) and
# lab4/ (bench.log, lab4_march.json/.md, plots) under $OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run}"
mkdir -p "$OUT/lab3_gpu" "$OUT/lab4"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
nvidia-smi -L
python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__)"
echo "== tests (compiled kernels; the interpreted ones are the CPU suite's)"
timeout "${TEST_TIMEOUT:-240}" python3 -m pytest -q -s -p no:cacheprovider --durations=8 \
    -k "not interpreted" tests/test_flat_bvh.py tests/test_cuda_tracer.py \
    tests/test_triton_tracer.py tests/test_triton_march.py 2>&1 | tee "$OUT/tests_cuda.log" | tail -40
echo "== bench/lab3_gpu.py"
timeout "${LAB3_TIMEOUT:-240}" python3 bench/lab3_gpu.py --out "$OUT/lab3_gpu" 2>&1 \
    | tee "$OUT/lab3_gpu/bench.log"
echo "== bench/lab4_march.py --only frame"
timeout "${LAB4_TIMEOUT:-150}" python3 bench/lab4_march.py --device cuda --only frame \
    --out "$OUT/lab4" 2>&1 | tee "$OUT/lab4/bench.log"
