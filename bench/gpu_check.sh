#!/usr/bin/env bash
# One call on a CUDA machine that checks what only a GPU can show after a round of changes
# (the CPU cases run in CI on every change):
#   1. every grader and course test's [cuda] cases (tests/, tests/hidden/; -k cuda), then
#      Lab 2's CUDA-graph walk tests, against the references in-process: tests_cuda.log;
#   2. meanwhile, generated mutants whose ids match ONLY graded with CUDA visible
#      (rtcourse mutants --generated --device auto): mistakes on paths only CUDA takes,
#      such as Lab 2's CUDA-graph walk: cuda_mutants.log, cuda_mutants.json.
# Needs python3, torch, triton, numpy, matplotlib, pytest; trimesh from .whl/ when present.
#
#   OUT=bench/results/<gpu>/check [ONLY=regex] [LIMIT=480] bash bench/gpu_check.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/check}"
mkdir -p "$OUT"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
{
    nvidia-smi -L
    python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__)"
    nproc
    git log -1 --format=%H 2>/dev/null
} > "$OUT/device.txt" 2>&1
( timeout "${LIMIT:-480}" python3 -m pytest tests -q -rs -p no:cacheprovider --ignore=tests/meta \
    -k cuda > "$OUT/tests_cuda.log" 2>&1
  echo "tests: exit $?" >> "$OUT/tests_cuda.log"
  timeout 200 python3 -m pytest -q -rs -p no:cacheprovider tests/meta/test_lab2_graph_cache.py \
    tests/meta/test_lab2_compiled.py >> "$OUT/tests_cuda.log" 2>&1
  echo "graph tests: exit $?" >> "$OUT/tests_cuda.log" ) &
tests=$!
if [ -n "${ONLY:-}" ]; then
    timeout "${LIMIT:-480}" python3 -m course.tools.cli mutants --generated --device auto \
        --only "$ONLY" --workers "${WORKERS:-4}" --json "$OUT/cuda_mutants.json" \
        > "$OUT/cuda_mutants.log" 2>&1
    echo "mutants: exit $?" >> "$OUT/cuda_mutants.log"
fi
wait $tests
for f in "$OUT"/*.log; do tail -n 12 "$f"; done
