#!/usr/bin/env bash
# Lab 1 on a CUDA machine, in one go: the speed/accuracy benchmark (torch variants x
# precisions, torch.compile, the Triton kernels' occupancy/speed sweep) and the tests of
# the Triton kernels, compiled and interpreted.
#
#   bash bench/gpu_lab1.sh            (from anywhere; it works in the repository root)
#
# Results: $OUT/lab1/ when OUT is set, else bench/results/<gpu-name>/lab1/ (JSON with the
# command line, Markdown table, plots, and the logs of both steps). Needs python3 with
# torch (CUDA), triton, numpy and matplotlib; trimesh is optional. PYTHON overrides python3.
set -uo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"  # `import course` without installing
PY="${PYTHON:-python3}"

if ! "$PY" -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)"; then
    echo "no CUDA device visible to $PY (torch.cuda.is_available() is False)" >&2
    exit 1
fi
if [ -n "${OUT:-}" ]; then
    out="$OUT/lab1"
else
    out="bench/results/$("$PY" -c "from course.measure.bench import device_name; print(device_name('cuda'))")/lab1"
fi
mkdir -p "$out"

status=0
"$PY" bench/lab1_intersect.py --device cuda --out "$out" 2>&1 | tee "$out/bench.log" || status=1
"$PY" -m pytest tests/test_triton_intersect.py -q -p no:cacheprovider 2>&1 \
    | tee "$out/pytest.log" || status=1
echo "results in $out (exit status $status)"
exit "$status"
