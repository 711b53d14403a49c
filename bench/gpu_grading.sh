#!/usr/bin/env bash
# Grading as the Gradescope container grades: the grader as root, the submission as the
# unprivileged user nobody (RTCOURSE_WORKER_USER), on a machine whose Python nobody can run.
#
# 1. The hostile submissions' tests (forged probe replies, readers of the hidden graders and
#    the results path, an unreadable interpreter) with that worker user: hostile.log.
# 2. One-off grading cost of every lab's reference, `rtcourse grade --lab N` with CUDA
#    hidden, each on its own core, in this tree and in OLD (an earlier commit's tree, e.g.
#    `git archive <commit> | tar -x -C .oldtree`), REPEATS rounds: times.tsv (tree, lab,
#    round, wall, user, sys seconds, score).
#
#   OUT=bench/results/<gpu>/grading OLD=.oldtree [REPEATS=2] bash bench/gpu_grading.sh
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-bench/results/gpu-run/grading}"
OUT="$(mkdir -p "$OUT" && cd "$OUT" && pwd)"
G=/tmp/rtcourse-grading
rm -rf "$G" && mkdir -p "$G/new"
# nobody must read the course, its packages and the interpreter: copy them out of /root.
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --target "$G/site" .whl/*.whl
fi
tar --exclude=.venv --exclude=.oldtree --exclude=.git --exclude=out -cf - . | tar -xf - -C "$G/new"
[ -n "${OLD:-}" ] && mkdir -p "$G/old" && cp -r "$OLD"/. "$G/old"
chmod -R a+rX "$G"
export PYTHONUNBUFFERED=1
nproc > "$OUT/device.txt"; nvidia-smi -L >> "$OUT/device.txt" 2>&1; command -v python3 >> "$OUT/device.txt"
( cd "$G/new" && PYTHONPATH="$G/site:$G/new" taskset -c 0,1 timeout 500 python3 -m pytest -q -rs \
    -p no:cacheprovider tests/meta/test_forgery.py tests/meta/test_grading_isolation.py \
    > "$OUT/hostile.log" 2>&1; echo "exit $?" >> "$OUT/hostile.log" ) &
printf 'tree\tlab\tround\twall\tuser\tsys\tscore\n' > "$OUT/times.tsv"
TIMEFORMAT="%R %U %S"
for round in $(seq "${REPEATS:-2}"); do
    core=2 pids=()
    for lab in 0 1 2 3 4 5 6; do
        for tree in new ${OLD:+old}; do
            (
                cd "$G/$tree" || exit
                rm -f "$OUT/$tree$lab.json"  # a round's score is its own, never the last round's
                t=$( { time CUDA_VISIBLE_DEVICES= RTCOURSE_WORKER_USER=nobody \
                    PYTHONPATH="$G/site:$G/$tree" taskset -c "$core" timeout 400 \
                    python3 -m course.tools.cli grade --lab "$lab" --json "$OUT/$tree$lab.json" \
                    > "$OUT/$tree${lab}_r$round.log" 2>&1 ; } 2>&1 )
                score=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['score'])" \
                    "$OUT/$tree$lab.json" 2>/dev/null)
                printf '%s\t%s\t%s\t%s\t%s\n' "$tree" "$lab" "$round" "${t// /	}" "$score" >> "$OUT/times.tsv"
                if [ -z "$score" ]; then  # no grade: say why where it comes back (times.tsv's neighbour)
                    { echo "== $tree lab $lab round $round"; tail -n 15 "$OUT/$tree${lab}_r$round.log"; } \
                        >> "$OUT/no_score.log"
                fi
            ) &
            pids+=($!) core=$((core + 1))
        done
    done
    wait "${pids[@]}"
done
wait
cat "$OUT/times.tsv"; tail -n 15 "$OUT/hostile.log"
