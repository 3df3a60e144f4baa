#!/usr/bin/env bash
# The full test suite: lint, format check, then pytest (unit + cross-process ROS 2 + CAN + bags).
#
# pytest runs in TEST_WORKERS parallel worker processes (pytest-xdist, default 2 = this project's
# machine size; TEST_WORKERS=0 runs in one process). Each worker owns its own ROS domain
# (test/conftest.py), so the ROS graphs of two workers never see each other. A test file runs whole
# on one worker (its module fixtures are built once); the slowest files start first. Extra
# arguments go to pytest (`make test ARGS="-k demo"`); the slowest tests are printed at the end.
set -uo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh || exit 1
echo "[test] ruff check + format check"
.venv/bin/ruff check . || exit 1
.venv/bin/ruff format --check . || { echo "[test] run 'make format' to fix formatting"; exit 1; }
workers=${TEST_WORKERS:-2}
if ! [[ "$workers" =~ ^[0-9]+$ ]]; then
  echo "[test] TEST_WORKERS must be a whole number of worker processes (0 = no workers), not '$workers'" >&2
  exit 2
fi
parallel=()
[ "$workers" -gt 0 ] && parallel=(-n "$workers" --dist loadfile --no-loadscope-reorder)
echo "[test] pytest (${workers} workers)"
start=$(date +%s)
.venv/bin/python -m pytest "${parallel[@]}" "$@"
rc=$?
echo "[test] pytest took $(( $(date +%s) - start )) s (load average now: $(cut -d' ' -f1-3 /proc/loadavg))"
if [ $rc -eq 5 ]; then
  echo "[test] pytest collected no tests (exit code 5): the suite is missing, failing" >&2
  exit 1
fi
exit $rc
