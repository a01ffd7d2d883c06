#!/usr/bin/env bash
# The grid world (tasks/gridworld) at a reduced scale: 5 autonomous agents against 5
# advised by a trained agent (the batch trains and checks the advisor first), then the
# report. Every command can be run again: finished runs are skipped, interrupted ones resume.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../../.." && pwd)
DATA=${DATA:-/work/gridworld-results}
IDEEPRL=${IDEEPRL:-$REPO/.venv/bin/ideeprl}
SCALE=(--episodes 80 --pretraining-steps 1000 --advice-budget 100 --max-episode-steps 64
       --set batch_size=32 --set memory_size=5000 --torch-threads 1)
"$IDEEPRL" batch --study gridworld --label G --task gridworld --methods autonomous agent \
  --agents 5 --seed 0 --data-dir "$DATA" --no-progress --advisor-check require \
  --advisor-attempts 3 --workers "${WORKERS:-1}" "${SCALE[@]}"
"$IDEEPRL" report --study gridworld --data-dir "$DATA" --out "$HERE/report"
