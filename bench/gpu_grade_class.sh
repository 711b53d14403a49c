#!/usr/bin/env bash
# rtcourse grade-class on a GPU machine: N synthetic students (default 100) of Lab 2 and of
# Lab 5, task 1, graded with CUDA hidden (--device cpu) and visible (--device auto), each
# against one-off grades of the same students on the same setting (bench/grade_class.py).
# Each setting gets LIMIT seconds (default 270); grade_class.json is written after each lab,
# so a setting cut short keeps its finished labs.
#
#   OUT=bench/results/<gpu>/grade_class [N=100] [LIMIT=270] [LABS="2 5"] [DEVICES="cpu auto"] \
#       bash bench/gpu_grade_class.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/grade_class}"
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
{ nproc; nvidia-smi -L; python3 -c "import torch; print('torch', torch.__version__)"; } \
    > "$OUT/device.txt" 2>&1
labs=()
for lab in ${LABS:-2 5}; do labs+=(--lab "$lab"); done
for device in ${DEVICES:-cpu auto}; do
    timeout "${LIMIT:-270}" python3 bench/grade_class.py --n "${N:-100}" "${labs[@]}" \
        --task 1 --time-limit 10 --device "$device" --out "$OUT/$device" > "$OUT/$device.log" 2>&1
    echo "exit $?" >> "$OUT/$device.log"
done
grep -h '"students_per_minute"\|class_per_student_over\|same_scores' "$OUT"/*.log
