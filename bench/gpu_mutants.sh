#!/usr/bin/env bash
# The generated-mutant score on a many-core machine: every lab at once, two workers each
# (CUDA hidden from the workers), each lab's table written as it finishes; meanwhile the
# tests on cuda and Lab 5's 1080p frame on the GPU (GPU=0: mutants only).
#
#   OUT=bench/results/nvidia-h200/mutants SAMPLE=40 SEEDS="1 2" [LABS="4 5"] [GPU=0] bash bench/gpu_mutants.sh
# writes OUT.tar.gz (the logs and each lab's JSON table).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/mutants}"
mkdir -p "$OUT"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
nproc > "$OUT/device.txt"; nvidia-smi -L >> "$OUT/device.txt" 2>&1
# On the GPU meanwhile (a few cores): every grader and course test on cpu + cuda, the CUDA-only
# course tests, and Lab 5's 1080p frame.
[ "${GPU:-1}" = 1 ] && ( timeout "${GPU_TIMEOUT:-450}" python3 -m pytest -q -p no:cacheprovider tests \
    --ignore=tests/meta tests/meta/test_lab2_graph_cache.py tests/meta/test_lab2_compiled.py \
    tests/meta/test_triton_froxel.py tests/meta/test_triton_raster.py --maxfail=30 \
    > "$OUT/tests_cuda.log" 2>&1
  echo "tests: exit $?" >> "$OUT/tests_cuda.log"
  timeout 100 python3 bench/lab5_froxel.py --device cuda --gpu-target >> "$OUT/lab5_frame.log" 2>&1
  echo "lab5 frame: exit $?" >> "$OUT/lab5_frame.log" ) &
for seed in ${SEEDS:-${SEED:-1}}; do
    for lab in ${LABS:-0 1 2 3 4 5 6}; do
        # Lab 0's tests time copies and frame loops: its mutants take ~10x longer.
        workers=$([ "$lab" = 0 ] && echo "${WORKERS0:-4}" || echo "${WORKERS:-2}")
        ( timeout "${MUTANT_TIMEOUT:-540}" python3 -m course.tools.cli mutants --generated \
            --lab "$lab" --sample "${SAMPLE:-40}" --seed "$seed" --workers "$workers" \
            --json "$OUT/lab${lab}_seed$seed.json" > "$OUT/lab${lab}_seed$seed.log" 2>&1
          echo "mutants lab $lab seed $seed: exit $?" >> "$OUT/lab${lab}_seed$seed.log" ) &
    done
done
wait
for f in "$OUT"/*.log; do tail -n 2 "$f"; done
# One archive: the machine sends back only a few files.
tar -C "$OUT" -czf "$OUT.tar.gz" . && rm -rf "$OUT"
