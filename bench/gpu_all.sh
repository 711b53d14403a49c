#!/usr/bin/env bash
# Everything only a GPU can show, in one go, on a CUDA machine with python3, torch,
# triton, numpy, matplotlib and pytest (trimesh optional: wheels in .whl/ are installed
# into a scratch folder when present).
#
#   OUT=/some/dir PART=tests bash bench/gpu_all.sh     (steps 1-2)
#   OUT=/some/dir PART=bench bash bench/gpu_all.sh     (steps 3-4)
#   OUT=/some/dir bash bench/gpu_all.sh                (all)
# DRIVERS="bench/lab1_intersect.py ..." picks bench drivers (DRIVER_TIMEOUT seconds each,
# default 150); GALLERY=0 skips the gallery.
#
# 1. every grader and course test on cpu+cuda, against the references, in-process;
# 2. the same graders against a copy of the references through the sandboxed worker
#    (CUDA inside the worker), with the score table;
# 3. each lab's speed/accuracy driver with --device cuda;
# 4. the demo gallery on cuda.
# Logs and results land in $OUT (a tarball of everything plus the main log).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run}"
mkdir -p "$OUT/run"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
log="$OUT/gpu_${PART:-all}.log"
{
    nvidia-smi -L
    python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__)"
    if [ "${PART:-all}" != bench ]; then
    echo "== 1. tests on cpu+cuda (references, in-process)"
    timeout 240 python3 -m pytest tests -q -p no:cacheprovider --ignore=tests/meta \
        --junitxml "$OUT/run/pytest_cuda.xml" 2>&1 | tail -25
    echo "== 2. sandboxed grading on cuda"
    rm -rf /tmp/sub && mkdir -p /tmp/sub && cp -r solutions/lab*_* /tmp/sub/  # with parts
    timeout 200 python3 -m course.tools.cli grade --impl /tmp/sub --json "$OUT/run/sandboxed_cuda.json" \
        2>&1 | tail -25
    fi
    if [ "${PART:-all}" != tests ]; then
    echo "== 3. benches"
    for driver in ${DRIVERS:-bench/lab*_*.py}; do
        name=$(basename "$driver" .py)
        echo "-- $driver"
        timeout "${DRIVER_TIMEOUT:-150}" python3 "$driver" --device cuda --out "$OUT/run/$name" 2>&1 | tail -8
    done
    [ "${GALLERY:-1}" = 1 ] && echo "== 4. gallery" && timeout 120 python3 -m course.tools.cli demo --device cuda --out "$OUT/run/gallery" 2>&1 | tail -12
    fi
} 2>&1 | tee "$log"
tar czf "$OUT/gpu_${PART:-all}.tar.gz" -C "$OUT" run "$(basename "$log")"
