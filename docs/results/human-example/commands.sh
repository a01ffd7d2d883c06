#!/usr/bin/env bash
# The example human study of issue 44 from nothing: a fresh SQLite data folder, an oracle
# pilot fitted into synthetic people, the server on a free loopback port, the study made
# from design.yaml, 7 synthetic participants through its link (`ideeprl rehearse`), one
# browser visit (visit.py, Chromium), the report while the learners still train (the
# command line and the dashboard's endpoint), then again once every learner has finished.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../../.." && pwd)
PY=${PY:-$REPO/.venv/bin/python}
export PYTHONPATH=$REPO
DATA=${DATA:-$(mktemp -d /tmp/human-example.XXXXXX)}
ideeprl() { nice -n 10 "$PY" -m cli.main "$@"; }
stamp() { echo "[$(date -u +%H:%M:%S)] $*"; }
echo "data folder: $DATA"

# 1. synthetic people: an oracle pilot (20 % wrong, decision times around 1.5 s) fitted
stamp "pilot"
ideeprl batch --study pilot --task gridworld --methods oracle --agents 2 --seed 0 \
  --episodes 2 --pretraining-steps 60 --advice-budget 40 --max-episode-steps 40 \
  --error-rate 0.2 --decision-time-median-s 1.5 --decision-time-sigma 0.5 \
  --set batch_size=16 --set memory_size=2000 --torch-threads 1 --workers 1 --no-progress \
  --data-dir "$DATA"
MODEL=$(ideeprl fit --study pilot --methods oracle --json --data-dir "$DATA" |
  "$PY" -c 'import json, sys; print(json.load(sys.stdin)["path"])')

# 2. the server on a free loopback port, one trainer slot (a shared 2-core machine)
PORT=$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
URL=http://127.0.0.1:$PORT
KEY=example-key-$$
export IDEEPRL_API_KEY=$KEY IDEEPRL_PUBLIC_URL=$URL IDEEPRL_MAX_TRAINERS=1
ideeprl study create --from "$HERE/design.yaml" --data-dir "$DATA" --json > "$DATA/study.json"
JOIN=$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["join_url"])' "$DATA/study.json")
STUDY=$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["id"])' "$DATA/study.json")
stamp "serve on $URL, study $STUDY, link $JOIN"
# (nice runs the server in its own process: $! is the server, and the trap stops it)
nice -n 10 "$PY" -m cli.main serve --port "$PORT" --data-dir "$DATA" --log-level warning \
  > "$DATA/serve.log" 2>&1 &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true; wait $SERVER 2>/dev/null || true' EXIT
until curl -sf "$URL/api/health" > /dev/null; do sleep 1; done
api() { curl -sf -H "X-API-Key: $KEY" "$@"; }

# 3. the visits: 7 synthetic participants, then one person in Chromium
stamp "rehearse"
ideeprl rehearse --model "$MODEL" --study-link "$JOIN" --participants 7 --seed 1 --speed 2 \
  --json > "$HERE/rehearsal.json"
stamp "browser visit"
"$PY" "$HERE/visit.py" "$JOIN" BROWSER-1
api "$URL/api/studies/$STUDY/conditions" > "$HERE/conditions.json"

# 4. the report while the learners still train
stamp "report while training: $(api "$URL/api/studies/$STUDY/sessions" |
  "$PY" -c 'import json, sys; print(sorted(s["status"] for s in json.load(sys.stdin)))')"
rm -rf "$HERE/report-training" "$HERE/report-finished" "$HERE/dashboard-training"
ideeprl report --study "$STUDY" --data-dir "$DATA" --out "$HERE/report-training" \
  --note "built while the learners still trained"
mkdir -p "$HERE/dashboard-training"
api -X POST -H 'Content-Type: application/json' -d '{}' "$URL/api/studies/$STUDY/report" \
  > "$HERE/dashboard-training/description.json"
api "$URL/api/studies/$STUDY/report/files/report.md" > "$HERE/dashboard-training/report.md"

# 5. again once every learner has finished
stamp "waiting for the learners"
until api "$URL/api/studies/$STUDY/sessions" | "$PY" -c '
import json, sys
done = [s["status"] for s in json.load(sys.stdin) if s.get("outcome") == "completed"]
sys.exit(0 if all(s in ("finished", "failed") for s in done) else 1)'
do sleep 10; done
stamp "report once finished"
ideeprl report --study "$STUDY" --data-dir "$DATA" --out "$HERE/report-finished" \
  --note "built once every learner had finished"
stamp "done"
