#!/usr/bin/env bash
# The reach task (tasks/reach) at a reduced scale: 5 autonomous agents against 5 advised by
# the oracle (the move that brings the hand nearest the ball), then the report. Every
# command can be run again: finished runs are skipped, interrupted ones resume.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../../.." && pwd)
DATA=${DATA:-/work/reach-results}
IDEEPRL=${IDEEPRL:-$REPO/.venv/bin/ideeprl}
SCALE=(--episodes 30 --pretraining-steps 500 --advice-budget 100 --max-episode-steps 30
       --set batch_size=32 --set memory_size=5000 --torch-threads 1)
"$IDEEPRL" batch --study reach --label R --task reach --methods autonomous oracle \
  --agents 5 --seed 0 --data-dir "$DATA" --no-progress --workers "${WORKERS:-1}" "${SCALE[@]}"
"$IDEEPRL" report --study reach --data-dir "$DATA" --out "$HERE/report"

# A scale at which both learn: 150 episodes, epsilon down to 1 % by about episode 90
LONGER=(--episodes 150 --pretraining-steps 500 --advice-budget 100 --max-episode-steps 30
        --set batch_size=32 --set memory_size=5000 --set epsilon_decay=0.998 --torch-threads 1)
"$IDEEPRL" batch --study reach-150 --label R150 --task reach --methods autonomous oracle \
  --agents 5 --seed 0 --data-dir "$DATA" --no-progress --workers "${WORKERS:-1}" "${LONGER[@]}"
"$IDEEPRL" report --study reach-150 --data-dir "$DATA" --out "$HERE/report-150"
