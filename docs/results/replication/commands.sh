#!/usr/bin/env bash
# The replication (docs/results/README.md): two advisors, then two resumable batches.
# Run from the repository root after `make setup`. DATA holds the batches' database, the
# advisors and the checkpoints (outside the work tree: several GB); every command can be
# run again to resume. `save` copies the database and the advisors (a few MB) into
# state/ to be committed; `restore` puts them back into a fresh DATA, so a later session
# goes on where this one stopped (finished runs are kept, unfinished ones start again).
set -euo pipefail
DATA=${DATA:-/work/replication}
OUT=docs/results/replication
BIN=${BIN:-.venv/bin}
mkdir -p "$DATA"

# 1. The advisors: autonomous learners of seed 100000 (apart from every compared seed),
#    trained under the settings of the comparison they advise in.
advisor() {  # name, then ideeprl train options
  local name=$1; shift
  if [ ! -f "$DATA/advisor-$name.pt" ]; then
    [ -f "$DATA/advisor-$name/checkpoint.pt" ] && resume=(--resume "$DATA/advisor-$name/checkpoint.pt") || resume=()
    nice -n 10 $BIN/ideeprl train --seed 100000 --torch-threads 1 --checkpoint-every 50 \
      --no-progress --out "$DATA/advisor-$name" "$@" "${resume[@]}"
    # Keep what an agent advisor reads (config and network, about 1 MB), not the memory.
    $BIN/python -c "
import sys, torch
from learner.checkpoint import read_checkpoint, write_checkpoint
s = read_checkpoint(sys.argv[1])
write_checkpoint(sys.argv[2], {'config': s['config'], 'seed': s['seed'],
    'metadata': s['metadata'], 'agent': {'network': s['agent']['network']}})
" "$DATA/advisor-$name/checkpoint.pt" "$DATA/advisor-$name.pt"
  fi
}

# (a) the paper's comparison as the authors made it: their learner, their realism, and
#     each method scored by the rule of its own script.
authors() {
  advisor authors --preset authors --reward-scheme authors-autonomous \
    --grasp-failure-rate 0.05 --knock-off-rate 0.05
  $BIN/ideeprl batch --study replication-authors --label authors \
    --methods autonomous agent --agents "${AGENTS:-10}" --seed 0 --preset authors \
    --per-method autonomous:reward_scheme=authors-autonomous \
    --per-method agent:reward_scheme=authors-interactive \
    --grasp-failure-rate 0.05 --knock-off-rate 0.05 \
    --advisor-checkpoint "$DATA/advisor-authors.pt" \
    --workers "${WORKERS:-1}" --torch-threads 1 --checkpoint-every 25 --nice 10 --no-progress \
    --data-dir "$DATA"
}

# (a') the authors' learner and scene with autonomous DeepRL trained and scored under the
#     advised arm's rule (authors-interactive): (a)'s agent-IDeepRL against it differs in
#     the advice only, which tells the advice apart from the reward each arm learned from.
authors_one_rule() {
  $BIN/ideeprl batch --study replication-authors --label authors-one-rule \
    --methods autonomous --agents "${AGENTS_ONE_RULE:-4}" --seed 0 --preset authors \
    --reward-scheme authors-interactive --grasp-failure-rate 0.05 --knock-off-rate 0.05 \
    --workers "${WORKERS:-1}" --torch-threads 1 --checkpoint-every 25 --nice 10 --no-progress \
    --data-dir "$DATA"
}

# (b) the same methods under one rule (the paper's text), the paper's learner settings.
paper() {
  advisor paper --preset paper
  $BIN/ideeprl batch --study replication-paper --label paper \
    --methods autonomous agent --agents "${AGENTS:-10}" --seed 0 --preset paper \
    --reward-scheme paper --advisor-checkpoint "$DATA/advisor-paper.pt" \
    --workers "${WORKERS:-1}" --torch-threads 1 --checkpoint-every 25 --nice 10 --no-progress \
    --data-dir "$DATA"
}

# (a')'s sessions: the finished authors-one-rule autonomous runs and (a)'s finished
# agent-IDeepRL runs of the same seeds, so the two arms pair up.
one_rule_sessions() {
  $BIN/python - "$DATA/ideeprl.sqlite3" <<'PY'
import sqlite3, sys
db = sqlite3.connect(sys.argv[1])
def finished(label, method):
    return dict(db.execute(
        "select json_extract(s.run, '$.seed'), s.id from sessions s join studies t on "
        "t.id = s.study_id where t.name = 'replication-authors' and s.label = ? and "
        "json_extract(s.run, '$.method') = ? and s.status = 'finished'", (label, method)
    ).fetchall())
autonomous, agent = finished("authors-one-rule", "autonomous"), finished("authors", "agent")
seeds = sorted(set(autonomous) & set(agent))
print(" ".join(str(ids[seed]) for seed in seeds for ids in (autonomous, agent)))
PY
}

# 2. The reports (what docs/results/ holds).
reports() {
  $BIN/ideeprl report --study replication-authors --data-dir "$DATA" --out "$OUT/authors" \
    --label authors --reference authors --allow-mismatch \
    --title "(a) The paper's comparison as the authors made it"
  # shellcheck disable=SC2046
  $BIN/ideeprl report --study replication-authors --data-dir "$DATA" \
    --out "$OUT/authors-one-rule" --reference authors \
    --sessions $(one_rule_sessions) \
    --title "(a') The authors' learner and scene under one rule (authors-interactive)"
  $BIN/ideeprl report --study replication-paper --data-dir "$DATA" --out "$OUT/paper" \
    --reference authors --title "(b) The same methods under one rule (paper)"
}

save() {
  mkdir -p "$OUT/state"
  $BIN/python -c "
import sqlite3, sys
src = sqlite3.connect(sys.argv[1]); dst = sqlite3.connect(sys.argv[2])
src.backup(dst)
# Unfinished runs' checkpoints stay behind: drop those runs, the batch creates them anew.
gone = 'select id from sessions where status != \"finished\"'
for table in ('steps', 'episodes', 'advice'):
    dst.execute(f'delete from {table} where session_id in ({gone})')
dst.execute(f'delete from sessions where id in ({gone})')
dst.commit(); dst.execute('vacuum'); dst.close()
" "$DATA/ideeprl.sqlite3" "$OUT/state/ideeprl.sqlite3"
  cp "$DATA"/advisor-*.pt "$OUT/state/"
  gzip -f -9 "$OUT/state/ideeprl.sqlite3"
}

restore() {
  [ -f "$DATA/ideeprl.sqlite3" ] || gunzip -c "$OUT/state/ideeprl.sqlite3.gz" > "$DATA/ideeprl.sqlite3"
  for f in "$OUT"/state/advisor-*.pt; do [ -f "$DATA/$(basename "$f")" ] || cp "$f" "$DATA/"; done
}

case "${1:-all}" in
  save) save ;;
  restore) restore ;;
  authors) authors ;;
  authors-one-rule) authors_one_rule ;;
  paper) paper ;;
  reports) reports ;;
  all) authors & authors_one_rule & paper & wait; reports ;;
esac
