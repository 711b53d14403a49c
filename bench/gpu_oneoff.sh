#!/usr/bin/env bash
# A one-off `rtcourse grade --impl FOLDER --lab N` of a copy of the references (a student's
# folder: sandboxed, as a student's grade runs) on a GPU machine, `--device auto` (CUDA
# visible: the graders' [cuda] cases run too) and `--device cpu` (CUDA hidden: the CPU
# alone, as Gradescope grades), one lab at a time on the whole machine, ROUNDS rounds with
# the two settings' order swapped each round: times.tsv (setting, lab, round, wall, user,
# sys seconds, score, max). Rows are appended as they finish, so a call cut short keeps them.
#
#   OUT=bench/results/<gpu>/grade_oneoff [ROUNDS=2] [LABS="0 1 2 3 4 5 6"] bash bench/gpu_oneoff.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/grade_oneoff}"
OUT="$(mkdir -p "$OUT" && cd "$OUT" && pwd)"
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl && export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
{ nproc; nvidia-smi -L; python3 -c "import torch; print('torch', torch.__version__)"; } \
    > "$OUT/device.txt" 2>&1
SUB="$(mktemp -d)" && cp -r solutions/lab*_* "$SUB"/  # a student's folder: sandboxed
printf 'setting\tlab\tround\twall\tuser\tsys\tscore\tmax\n' > "$OUT/times.tsv"
TIMEFORMAT="%R %U %S"
one() {  # one (setting, lab, round): a row of times.tsv
    local setting=$1 lab=$2 round=$3
    local json="$OUT/$setting${lab}_r$round.json" log="$OUT/$setting${lab}_r$round.log" t
    t=$( { time timeout 150 python3 -m course.tools.cli grade --device "$setting" \
        --impl "$SUB" --lab "$lab" --json "$json" > "$log" 2>&1 ; } 2>&1 )
    local score
    score=$(python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['score'], d['max_score'], sep='\t')" \
        "$json" 2>/dev/null || printf '\t')
    printf '%s\t%s\t%s\t%s\t%s\n' "$setting" "$lab" "$round" "${t// /	}" "$score" >> "$OUT/times.tsv"
}
for round in $(seq "${ROUNDS:-2}"); do
    order="cpu auto"; [ $((round % 2)) = 0 ] && order="auto cpu"
    for lab in ${LABS:-0 1 2 3 4 5 6}; do
        for setting in $order; do one "$setting" "$lab" "$round"; done
    done
done
cat "$OUT/times.tsv"
