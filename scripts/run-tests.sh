#!/usr/bin/env bash
# The full test suite: lint, format check, then pytest (unit + cross-process ROS 2 + CAN + bags).
#
# pytest runs in TEST_WORKERS parallel worker processes (pytest-xdist, default one per CPU, at most
# 16; TEST_WORKERS=0 runs in one process). Each worker owns its own ROS domain (test/conftest.py), so
# the ROS graphs of two workers never see each other, and one CPU (every process it starts inherits
# it: a lockstep graph's messages never cross cores; FRICTION_TEST_PIN=0 turns that off). More
# workers than CPUs share them (worker i on CPU i mod n): on 2 CPUs, 4 workers took the parallel
# phase from 528 s to 457 s, but the wall-clock CAN hold tests then shared a CPU with another
# worker's computation and failed in one run of three, so the default stays one per CPU. A test file runs whole
# on one worker (its module fixtures are built once); the slowest files start first. Tests marked
# `serial` (wall-clock timing that a fully loaded CPU breaks) run afterwards, alone. Extra arguments
# go to pytest (`make test ARGS="-k demo"`); each phase prints its slowest tests.
set -uo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh --deps || exit 1
# one process compiles the numba kernels into their on-disk cache (the workers and nodes load it),
# while the messages are built and the package installed: it needs only the dependencies
mkdir -p build
.venv/bin/python scripts/warm-numba-cache.py > build/warm-numba-cache.log 2>&1 &
warm=$!
./scripts/bootstrap.sh || { kill $warm 2>/dev/null; exit 1; }
echo "[test] ruff check + format check"
.venv/bin/ruff check . || { kill $warm 2>/dev/null; exit 1; }
.venv/bin/ruff format --check . || { echo "[test] run 'make format' to fix formatting"; kill $warm 2>/dev/null; exit 1; }
cpus=$(nproc)
default_workers=$(( cpus > 16 ? 16 : cpus ))
workers=${TEST_WORKERS:-$default_workers}
if ! [[ "$workers" =~ ^[0-9]+$ ]]; then
  echo "[test] TEST_WORKERS must be a whole number of worker processes (0 = no workers), not '$workers'" >&2
  exit 2
fi
parallel=()
[ "$workers" -gt 0 ] && parallel=(-n "$workers" --dist loadfile --no-loadscope-reorder)
# pytest's exit code 5 = no test selected (ARGS may select none of a phase): fine if the other ran some
phase() { .venv/bin/python -m pytest "$@"; local rc=$?; [ $rc -eq 5 ] && return 5; return $rc; }
start=$(date +%s)
wait $warm || { cat build/warm-numba-cache.log; echo "[test] the numba kernels did not compile" >&2; exit 1; }
cat build/warm-numba-cache.log
# the workers share the cores: each one (and the node processes it starts) gets its share of the
# compiled kernels' threads, not a full set each (2 workers x 2 threads on 2 cores fought for them)
threads=$(( $(nproc) / (workers > 0 ? workers : 1) ))
[ "$threads" -lt 1 ] && threads=1
echo "[test] pytest, ${workers} workers: every test not marked serial (${threads} kernel thread(s) each)"
NUMBA_NUM_THREADS=$threads phase "${parallel[@]}" -m "not serial" "$@"
rc1=$?
echo "[test] pytest, alone: the tests marked serial (wall-clock timing a fully loaded CPU breaks)"
phase -m serial "$@"
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
