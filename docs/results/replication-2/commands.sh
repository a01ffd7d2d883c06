#!/usr/bin/env bash
# The replication at 10 + 10 (docs/results/plan.md), every arm from the tag `replication-2`.
#
#   git worktree add /work/rep2 replication-2      # the fixed code version
#   docs/results/replication-2/commands.sh restore # a fresh machine: the committed state back
#   docs/results/replication-2/commands.sh all     # this CPU kind's arms (plan.md, amendment 3)
#   docs/results/replication-2/commands.sh save    # the state to commit (database parts, advisors)
#   POPULATION=1 docs/results/replication-2/commands.sh paper   # its runs alone, in pairs
#   WORKERS=1 ...                                                # one run at a time
#
# Runs in populations and alone take the same course to the bit (../populations/), so
# POPULATION only changes how a session's time is spent: with 1, two runs at a time finish
# one after another (none is lost when a session ends mid-batch); by default a worker's
# population of up to 8 finishes together.
#
# Runs from the main checkout's venv but imports the tag's code (the worktree comes first on
# sys.path); each session records its code version, so a run from other code shows in the
# report's audit. Every command can be run again: finished runs are skipped, interrupted
# ones resume from their checkpoints, and runs whose checkpoints did not survive (a new
# machine) start again. DATA holds the database, the advisors and the checkpoints.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../../.." && pwd)
DATA=${DATA:-/work/replication-2}
CODE=${CODE:-/work/rep2}
PY=${PY:-$REPO/.venv/bin/python}
STATE=$HERE/state
mkdir -p "$DATA"

# (`server.cli`: the command line's module at the tag, before the folders were split by program.)
batch() {  # study, label, then ideeprl batch options
  local study=$1 label=$2; shift 2
  (cd "$CODE" && "$PY" -m server.cli batch --study "$study" --label "$label" --seed 0 \
    --agents "${AGENTS:-10}" --torch-threads 1 --checkpoint-every 25 --no-progress \
    --advisor-check require --advisor-attempts 5 --data-dir "$DATA" \
    ${POPULATION:+--population "$POPULATION"} ${WORKERS:+--workers "$WORKERS"} "$@")
}
AUTHORS=(--preset authors --grasp-failure-rate 0.05 --knock-off-rate 0.05)

# The plan's amendment 3: every arm runs on one CPU kind. amx: Xeon with AVX-512 BF16 and
# AMX; bf16: EPYC with AVX-512 BF16, no AMX; avx2: neither (float32 only).
cpu_kind() {
  if grep -qw amx_tile /proc/cpuinfo; then echo amx
  elif grep -qw avx512_bf16 /proc/cpuinfo; then echo bf16
  else echo avx2; fi
}
on() {  # on KIND ARM: refuse ARM on another CPU kind
  local have; have=$(cpu_kind)
  [ "$have" = "$1" ] || { echo "$2 runs on the '$1' CPU kind (plan.md, amendment 3); this machine is '$have'"; return 1; }
}
paper_advisor() {  # (b)'s checked advisor, which advises the A arms too (amendment 1)
  sqlite3 "$DATA/ideeprl.sqlite3" "select s.checkpoint_path from sessions s join studies t on t.id = s.study_id where t.name = 'replication-2-paper' and s.label = 'B advisor' and s.status = 'finished' limit 1"
}

# (b) the paper's learner (linear head, as SPEC decides), one rule: B-auto, B-agent, B-procedure.
paper() { on bf16 "B (B-procedure)" || return 1; batch replication-2-paper B --methods autonomous agent procedure --preset paper --reward-scheme paper; }

# (a') the authors' learner and scene under one rule: A-auto, A-agent, A-procedure. The
# autonomous runs of label A-auto (the population equivalence arm) are the same runs.
authors() { batch replication-2-authors A --methods autonomous agent procedure "${AUTHORS[@]}" --reward-scheme authors-interactive; }

# The plan's amendment 1, step 2: all five `authors` advisors failed their check, so A-agent
# and A-procedure are advised by (b)'s checked `paper` advisor, checked again here under A's
# own scenario (`--advisor-check require` refuses it if it fails there).
authors_paper_advisor() {
  on amx "A-agent, A-procedure" || return 1
  local advisor
  advisor=$(paper_advisor)
  [ -n "$advisor" ] || { echo "authors-paper-advisor: (b)'s advisor is not trained yet: run 'paper' first"; return 1; }
  batch replication-2-authors A --methods autonomous agent procedure "${AUTHORS[@]}" \
    --reward-scheme authors-interactive --advisor-checkpoint "$advisor" "$@"
}

# (a) as the authors made it: their autonomous arm learned and scored under its own rule,
# against A-agent (the report withholds a primary test: two reward rules).
authors_own() { on amx A-auto-own || return 1; batch replication-2-authors A-own --methods autonomous "${AUTHORS[@]}" --reward-scheme authors-autonomous; }

# The float32 control of the authors' preset, 3 + 3, advised by A-agent's checked advisor.
# Its autonomous arm needs no advisor, and the plan lets float32 arms run on the AVX2-only
# EPYC (bfloat16 ones never): `fp32-auto` runs it alone, before an advisor exists.
FP32=(--reward-scheme authors-interactive --precision fp32)
# FP32_AGENTS=10: seeds 0-9, the plan's amendment 2 (exploratory; the plan's arm is 0-2).
fp32_auto() { AGENTS=${FP32_AGENTS:-3} batch replication-2-authors A-fp32 --methods autonomous "${AUTHORS[@]}" "${FP32[@]}"; }
fp32() {
  on amx A-agent-fp32 || return 1
  local advisor
  advisor=$(sqlite3 "$DATA/ideeprl.sqlite3" "select json_extract(s.run, '$.advisor_checkpoint') from sessions s join studies t on t.id = s.study_id where t.name = 'replication-2-authors' and json_extract(s.run, '$.method') = 'agent' and json_extract(s.run, '$.config.precision') != 'fp32' limit 1")
  [ -n "$advisor" ] || { echo "fp32: A-agent's advisor is not trained yet: run 'authors' first"; return 1; }
  AGENTS=3 batch replication-2-authors A-fp32 --methods autonomous agent "${AUTHORS[@]}" \
    "${FP32[@]}" --advisor-checkpoint "$advisor"
}

# The population equivalence arms (issue "The paper's experiment in half an hour"): the same
# seeds' autonomous runs alone (`--population 1`), against B's and A's (in populations).
alone() {
  batch equivalence-paper-alone B-alone --methods autonomous --preset paper --reward-scheme paper --population 1
  batch equivalence-authors-alone A-auto-alone --methods autonomous "${AUTHORS[@]}" --reward-scheme authors-interactive --population 1
}

# Amendment 3: A-auto again on the AMX Xeon, so that comparison 2's arms share a CPU kind.
# Its own study: a run's identity is its study and its spec, so in replication-2-authors
# the batch would find A-auto's finished EPYC runs and skip them.
authors_auto_amx() {
  on amx A-auto-amx || return 1
  batch replication-2-authors-amx A-auto-amx --methods autonomous "${AUTHORS[@]}" --reward-scheme authors-interactive "$@"
}
# Amendment 3: B-agent (run in populations, resumed) again alone on the BF16 EPYC, to be
# compared with it step by step.
paper_agent_alone() {
  on bf16 B-agent-alone || return 1
  local advisor
  advisor=$(paper_advisor)
  [ -n "$advisor" ] || { echo "paper-agent-alone: (b)'s advisor is not in $DATA"; return 1; }
  batch equivalence-paper-agent-alone B-agent-alone --methods agent --preset paper \
    --reward-scheme paper --advisor-checkpoint "$advisor" --population 1 "$@"
}

# The saved state (state/): the database in parts of one study and label each, every part
# under 50 MB, and the advisors with the checks stored beside them (state.py).
save() { (cd "$CODE" && PYTHONPATH="$CODE" "$PY" "$HERE/state.py" save "$DATA" "$STATE"); }
restore() { (cd "$CODE" && PYTHONPATH="$CODE" "$PY" "$HERE/state.py" restore "$STATE" "$DATA"); }

case "${1:-all}" in
  save) save ;;
  restore) restore ;;
  paper) paper ;;
  authors) authors ;;
  authors-paper-advisor) shift; authors_paper_advisor "$@" ;;
  authors-own) authors_own ;;
  fp32) fp32 ;;
  fp32-auto) fp32_auto ;;
  alone) alone ;;
  authors-auto-amx) shift; authors_auto_amx "$@" ;;
  paper-agent-alone) shift; paper_agent_alone "$@" ;;
  kind) cpu_kind ;;
  # What amendment 3 gives this machine's CPU kind, in its order.
  all) case $(cpu_kind) in
         amx) authors_paper_advisor; authors_auto_amx; authors_own; fp32 ;;
         bf16) paper; paper_agent_alone ;;
         *) echo "no run of the plan is left for the AVX2-only CPU kind (plan.md, amendment 3)" ;;
       esac ;;
  *) echo "usage: $0 [save|restore|kind|paper|authors|authors-paper-advisor|authors-auto-amx|authors-own|fp32|fp32-auto|paper-agent-alone|alone|all]"; exit 2 ;;
esac
