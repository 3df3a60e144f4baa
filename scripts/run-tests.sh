#!/usr/bin/env bash
# The full test suite: lint, format check, then pytest (unit + cross-process ROS 2 + CAN + bags).
#
# pytest runs in two phases of parallel worker processes (pytest-xdist). Each worker owns its own ROS
# domain (test/conftest.py), so the ROS graphs of two workers never see each other, and one CPU
# (every process it starts inherits it: a lockstep graph's messages never cross cores;
# FRICTION_TEST_PIN=0 turns that off); worker i is on CPU i mod n.
#   1. every test not marked `realtime`: TEST_WORKERS workers, default two per CPU (at most 16): a
#      ROS test waits for its graph's discovery or messages part of its time, and the second worker
#      on the CPU computes meanwhile.
#   2. the tests marked `realtime` (1 kHz loops on the wall clock, which a shared CPU breaks): one
#      worker per CPU (REALTIME_WORKERS), after phase 1.
# TEST_WORKERS=0 runs everything in one process. A test file runs whole on one worker (its module
# fixtures are built once); the slowest files start first. Extra arguments go to pytest
# (`make test ARGS="-k demo"`); each phase prints its slowest tests.
set -uo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh --deps || exit 1
# two processes compile the numba kernels into their on-disk cache (the workers and nodes load it),
# the plants' and the fit's, while the messages are built and the package installed: they need only
# the dependencies
mkdir -p build
.venv/bin/python scripts/warm-numba-cache.py plants > build/warm-numba-plants.log 2>&1 &
warm_plants=$!
.venv/bin/python scripts/warm-numba-cache.py fit > build/warm-numba-fit.log 2>&1 &
warm_fit=$!
stop_warm() { kill $warm_plants $warm_fit 2>/dev/null; }
./scripts/bootstrap.sh || { stop_warm; exit 1; }
echo "[test] ruff check + format check"
.venv/bin/ruff check . || { stop_warm; exit 1; }
.venv/bin/ruff format --check . || { echo "[test] run 'make format' to fix formatting"; stop_warm; exit 1; }
cpus=$(nproc)
workers=${TEST_WORKERS:-$(( 2 * cpus > 16 ? 16 : 2 * cpus ))}
rt_workers=${REALTIME_WORKERS:-$(( cpus > 16 ? 16 : cpus ))}
for w in "$workers" "$rt_workers"; do
  if ! [[ "$w" =~ ^[0-9]+$ ]]; then
    echo "[test] TEST_WORKERS and REALTIME_WORKERS must be whole numbers of worker processes (0 = no workers), not '$w'" >&2
    exit 2
  fi
done
[ "$workers" -eq 0 ] && rt_workers=0
xdist() { [ "$1" -gt 0 ] && echo "-n $1 --dist loadfile --no-loadscope-reorder"; }
# pytest's exit code 5 = no test selected (ARGS may select none of a phase): fine if the other ran some
phase() { .venv/bin/python -m pytest "$@"; local rc=$?; [ $rc -eq 5 ] && return 5; return $rc; }
# pytest caches each test module's rewritten bytecode (each worker of each phase collects every
# module: 6.6 s each without the cache, 3.3 s with it); a PYTHONDONTWRITEBYTECODE of the caller's
# environment would stop it
unset PYTHONDONTWRITEBYTECODE
start=$(date +%s)
# while the fit's kernels compile (one CPU): one collection writes that cache, so the workers of
# both phases read it instead of each rewriting every module at once
.venv/bin/python -m pytest --collect-only -q -p no:cacheprovider "$@" > build/collect.log 2>&1
warm_rc=0
wait $warm_plants || warm_rc=1
wait $warm_fit || warm_rc=1
cat build/warm-numba-plants.log build/warm-numba-fit.log
[ $warm_rc -eq 0 ] || { echo "[test] the numba kernels did not compile" >&2; exit 1; }
# the workers share the cores: each one (and the node processes it starts) gets its share of the
# compiled kernels' threads, not a full set each (2 workers x 2 threads on 2 cores fought for them)
threads=$(( cpus / (workers > 0 ? workers : 1) ))
[ "$threads" -lt 1 ] && threads=1
echo "[test] pytest, ${workers} workers: every test not marked realtime (${threads} kernel thread(s) each)"
# shellcheck disable=SC2046
NUMBA_NUM_THREADS=$threads phase $(xdist "$workers") -m "not realtime" "$@"
rc1=$?
echo "[test] pytest, ${rt_workers} workers, one per CPU: the tests marked realtime (1 kHz on the wall clock)"
rt_threads=$(( cpus / (rt_workers > 0 ? rt_workers : 1) ))
[ "$rt_threads" -lt 1 ] && rt_threads=1
# shellcheck disable=SC2046
NUMBA_NUM_THREADS=$rt_threads phase $(xdist "$rt_workers") -m realtime "$@"
rc2=$?
echo "[test] pytest took $(( $(date +%s) - start )) s (load average now: $(cut -d' ' -f1-3 /proc/loadavg))"
if [ $rc1 -eq 5 ] && [ $rc2 -eq 5 ]; then
  echo "[test] pytest collected no tests (exit code 5): the suite is missing, failing" >&2
  exit 1
fi
for rc in $rc1 $rc2; do
  [ $rc -ne 0 ] && [ $rc -ne 5 ] && exit $rc
done
exit 0
