#!/usr/bin/env bash
# Evaluative feedback on the sorting task (issue "The paper's other strategy"), at a reduced
# scale: under one reward rule (colour: blue right, red left; the paper's rewards), an
# oracle evaluator that never errs (error rate 0) judges the learner's own moves in the
# last 100 steps of the random practice (early advising), and the learner uses each rating
# in one of two ways (design/shaping.json: the rated step's reward plus the rating;
# design/rating_model.json: that, and a model of the rating shapes every later step),
# against autonomous agents: 10 + 10 + 10 agents, seeds 0 to 9 in every arm (paired).
# Then the report. Every command can be run again: finished runs are skipped, interrupted
# ones resume from their checkpoints. README.md names the scale and the compute.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../../.." && pwd)
DATA=${DATA:-/work/evaluative-sorting}
IDEEPRL=${IDEEPRL:-$REPO/.venv/bin/ideeprl}
AGENTS=${AGENTS:-10}
OUT=${OUT:-$HERE/report}
SCALE=(--episodes "${EPISODES:-60}" --pretraining-steps "${PRETRAINING:-1000}"
       --advice-budget "${BUDGET:-100}" --torch-threads 1 --workers "${WORKERS:-1}"
       --population 1 --seed 0 --agents "$AGENTS" --no-progress --data-dir "$DATA")
STUDY=(--study evaluative-sorting)
# autonomous agents, and the oracle's ratings used by shaping the rated step alone
"$IDEEPRL" batch "${STUDY[@]}" --label shaping --methods autonomous oracle \
  --run "$HERE/design/shaping.json" "${SCALE[@]}"
# the same ratings (same seeds, same judged steps) used by a model of the rating too
"$IDEEPRL" batch "${STUDY[@]}" --label rating_model --methods oracle \
  --run "$HERE/design/rating_model.json" "${SCALE[@]}"
"$IDEEPRL" report "${STUDY[@]}" --data-dir "$DATA" --out "$OUT"
