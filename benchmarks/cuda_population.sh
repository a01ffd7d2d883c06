#!/usr/bin/env bash
# Populations on CUDA, once, on a machine with an NVIDIA GPU whose Python has torch with CUDA
# but none of this project's other needs and no network (how the lent H200 of 2026-12-04 was
# used): it installs the wheels in WHEELS (pip download ... --python-version of that
# machine), builds pybullet from its source there (PyPI has no wheel of pybullet 3.2.7 for
# Python 3.12; WHEELS/pybullet-3.2.7-src.tar.xz is the sdist less its example data), then:
#   1. the CUDA test of tests/learner/test_population.py;
#   2. benchmarks.bench_population_batch: one population of 10 on the GPU against one run;
#   3. the paper's experiment through `ideeprl batch` (21 runs at paper scale, fast motion),
#      populations on the GPU, its wall time and each run's R_T and numerics.
# Usage: benchmarks/cuda_population.sh WHEELS OUT [DEADLINE_S]
# Everything it prints goes to OUT/log; it stops the experiment DEADLINE_S (default 540)
# seconds after it started, and says how far it got.
set -u
WHEELS=$(realpath "$1"); OUT=$(realpath "$2"); DEADLINE=${3:-540}
START=$(date +%s); mkdir -p "$OUT"; exec > >(tee -a "$OUT/log") 2>&1
export PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
left() { echo $(( DEADLINE - ($(date +%s) - START) )); }
stage() { echo; echo "== $1 (t=$(( $(date +%s) - START )) s; load $(cut -d' ' -f1-3 /proc/loadavg))"; }

stage "machine"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
grep -m1 "model name" /proc/cpuinfo; nproc; python3 --version
python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.is_available())"

stage "install: wheels, and pybullet built from source"
SITE=/tmp/ideeprl-site; mkdir -p $SITE
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target $SITE "$WHEELS"/*.whl || exit 1
mkdir -p /tmp/pb && tar xJf "$WHEELS"/pybullet-3.2.7-src.tar.xz -C /tmp/pb || exit 1
( cd /tmp/pb/pybullet-3.2.7 && python3 setup.py build_ext --inplace > /tmp/pb/build.log 2>&1 ) \
  || { tail -30 /tmp/pb/build.log; exit 1; }
find /tmp/pb/pybullet-3.2.7 -maxdepth 4 -name "pybullet*.so" -exec cp {} $SITE/ \; && cp -r /tmp/pb/pybullet-3.2.7/examples/pybullet/gym/pybullet_data $SITE/
export PYTHONPATH=$SITE:$PWD
python3 -c "import pybullet, sqlalchemy, pydantic, gymnasium; print('pybullet', pybullet.__file__)" || exit 1

nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader -l 2 > "$OUT/gpu.csv" &
stage "1. the CUDA test"
timeout 120 python3 -m pytest -q -p no:cacheprovider tests/learner/test_population.py -k cuda

stage "2. bench_population_batch on the GPU: one run, one population of 10"
timeout 180 python3 -m benchmarks.bench_population_batch --sizes 1 10 --workers 1 --episodes 2 \
  --pretraining-steps 200 --repeats 1 --profile-sizes 10 --log "$OUT/population-batch-cuda.log"

stage "3. the paper's experiment through ideeprl batch, populations on the GPU ($(left) s left)"
DATA=/tmp/paper-cuda; rm -rf $DATA
T0=$(date +%s)
timeout $(( $(left) - 25 )) python3 -m cli batch --study paper-cuda --methods autonomous agent \
  --agents 10 --preset paper --reward-scheme paper --torch-threads 1 --device cuda \
  --workers 4 --population 5 --advisor-check record --no-progress --data-dir $DATA
echo "batch exit $? after $(( $(date +%s) - T0 )) s (load $(cut -d' ' -f1-3 /proc/loadavg))"
python3 - "$DATA" <<'PY'
import json, sys
from pathlib import Path
from sqlalchemy import create_engine, text
db = next(Path(sys.argv[1]).rglob("*.sqlite3"))
with create_engine(f"sqlite:///{db}").connect() as c:
    for sid, status, started, finished, run, prov in c.execute(text(
            "SELECT id, status, started_at, finished_at, run, provenance FROM sessions")):
        run, last = json.loads(run), (json.loads(prov) or [{}])[-1]
        rt, episodes = c.execute(text(
            "SELECT sum(collected_reward), count(*) FROM episodes WHERE session_id=:s AND stage='train'"),
            {"s": sid}).one()
        print(f"session {sid} {run['method']} seed {run['seed']} {status} {started} -> {finished}: "
              f"{episodes} training episodes, reward sum {rt}; numerics {last.get('numerics')}, "
              f"population {last.get('population')}, torch {last.get('torch')}, cpu {last.get('cpu')}")
    for stage, n, first, final in c.execute(text(
            "SELECT stage, count(*), min(wall_time), max(wall_time) FROM steps GROUP BY stage")):
        print(f"{stage}: {n} steps over {final - first:.0f} s")
PY
kill %1 2>/dev/null; sort -t, -k2 -n "$OUT/gpu.csv" | tail -1 | sed 's/^/GPU peak: /'
stage "done"
