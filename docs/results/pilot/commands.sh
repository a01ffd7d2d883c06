#!/usr/bin/env bash
# The pilot of issue "More from every participant" (docs/results/pilot/README.md): oracle
# sessions standing in for people (an error rate and decision times), an advisor fitted to
# them, sessions advised by the fitted advisor, the people's advice replayed into the other
# learner preset, and power analyses. Run from the repository root after `make setup`;
# every step resumes (run it again to finish an interrupted one).
set -euo pipefail
DATA=${DATA:-/work/pilot}
OUT=docs/results/pilot
PY=${PY:-.venv/bin/python}
ideeprl() { nice -n 5 "$PY" -m server.cli "$@" --data-dir "$DATA"; }
# Reduced scale (stated in the README): the paper's pretraining and advice, 10 episodes.
SCALE=(--episodes 10 --workers 2 --torch-threads 1 --no-progress)
mkdir -p "$DATA" "$OUT"

people() {  # 1. "people": the oracle, wrong 20 % of the time, deciding in 2.5 s (median)
  ideeprl batch --study pilot --label people --methods oracle --agents 6 \
    --error-rate 0.2 --decision-time-median-s 2.5 --decision-time-sigma 0.6 "${SCALE[@]}"
}
fit() {  # 2. a model of them, from their recorded advice
  ideeprl fit --study pilot --methods oracle --json > "$OUT/fitted_model.json"
}
fitted() {  # 3. sessions advised by the fitted model
  local model
  model=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['path'])" "$OUT/fitted_model.json")
  ideeprl batch --study pilot --label fitted --methods fitted --agents 6 \
    --fitted-model "$model" "${SCALE[@]}"
}
replayed() {  # 4. the people's advice, by order, into the authors' learner
  ideeprl batch --study pilot --label replayed-authors --methods replayed \
    --replay-study 1 --replay-methods oracle --preset authors "${SCALE[@]}"
}
report() {
  ideeprl report --study pilot --out "$OUT/report" --baseline oracle
  gzip -c "$DATA/ideeprl.sqlite3" > "$OUT/ideeprl.sqlite3.gz"  # the pilot database (export it with ideeprl export)
}
power() {  # the paper's comparison planned with the effect sizes the replication measured
  local REPL=${REPL:-/work/replication-copy}
  mkdir -p "$REPL"
  gunzip -c docs/results/replication/state/ideeprl.sqlite3.gz > "$REPL/ideeprl.sqlite3"
  local db=(--data-dir "$REPL" --database-url "sqlite:///$REPL/ideeprl.sqlite3")
  # (b) the paper's learner under one rule, 10 + 10
  nice "$PY" -m server.cli power --study replication-paper "${db[@]}" --out "$OUT/power-b" \
    > "$OUT/power-b.txt"
  # (a') the authors' learner under one rule: (a)'s advised runs against the one-rule ones
  nice "$PY" -m server.cli power --study replication-authors --sessions 22 24 26 47 53 48 49 \
    50 51 54 "${db[@]}" --out "$OUT/power-a-prime" > "$OUT/power-a-prime.txt"
}
case "${1:-all}" in
  all) people; fit; fitted; replayed; report; power ;;
  *) "$@" ;;
esac
