#!/usr/bin/env bash
# One call on a CUDA machine that checks what only a GPU can show after a round of changes:
#   1. every grader and course test (tests/, tests/hidden/) on cpu + cuda, references
#      in-process;
#   2. the same graders against a copy of the references through the sandboxed worker,
#      CUDA inside the worker (the score table);
#   3. Lab 2's CUDA-graph walk tests; Lab 5's 1080p frame (torch and fused);
#   4. then, on the machine's CPU cores (CUDA hidden), a sample of the generated
#      mutants (run after the rest: sharing the CPUs with it, every part ran out of time) (rtcourse mutants --generated --sample N).
# Needs python3, torch, triton, numpy, matplotlib, pytest; trimesh from .whl/ when present.
#
#   OUT=bench/results/nvidia-h200/check SAMPLE=60 bash bench/gpu_check.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/check}"
mkdir -p "$OUT"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
CLI="python3 -m course.tools.cli"
{
    nvidia-smi -L
    python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__)"
    nproc
} > "$OUT/device.txt" 2>&1
( timeout "${TEST_TIMEOUT:-280}" python3 -m pytest tests -q -p no:cacheprovider --ignore=tests/meta \
    --maxfail=30 > "$OUT/tests_cuda.log" 2>&1
  echo "tests: exit $?" >> "$OUT/tests_cuda.log" ) &
tests=$!
rm -rf /tmp/sub && mkdir -p /tmp/sub && cp -r solutions/lab*_* /tmp/sub/  # with parts
( timeout "${GRADE_TIMEOUT:-280}" $CLI grade --impl /tmp/sub --json "$OUT/sandboxed_cuda.json" \
    > "$OUT/sandboxed_cuda.log" 2>&1
  echo "grade: exit $?" >> "$OUT/sandboxed_cuda.log" ) &
grade=$!
wait $tests $grade
{
    timeout 100 python3 -m pytest -q -p no:cacheprovider tests/meta/test_lab2_graph_cache.py \
        tests/meta/test_lab2_compiled.py 2>&1 | tail -15
    echo "lab2 graph tests: exit ${PIPESTATUS[0]}"
    timeout 100 python3 bench/lab5_froxel.py --device cuda --gpu-target 2>&1 | tail -15
    echo "lab5 frame: exit ${PIPESTATUS[0]}"
} > "$OUT/extras.log" 2>&1
( timeout "${MUTANT_TIMEOUT:-330}" $CLI mutants --generated --sample "${SAMPLE:-60}" \
    --workers "${WORKERS:-10}" --json "$OUT/generated_mutants.json" > "$OUT/generated_mutants.log" 2>&1
  echo "mutants: exit $?" >> "$OUT/generated_mutants.log" ) 
for f in "$OUT"/*.log; do tail -n 3 "$f"; done
