#!/usr/bin/env bash
# The full test suite: lint, format check, then pytest (unit + cross-process ROS 2 + CAN + bags).
set -uo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh || exit 1
echo "[test] ruff check + format check"
.venv/bin/ruff check . || exit 1
.venv/bin/ruff format --check . || { echo "[test] run 'make format' to fix formatting"; exit 1; }
echo "[test] pytest"
.venv/bin/python -m pytest "$@"
rc=$?
if [ $rc -eq 5 ]; then
  echo "[test] pytest collected no tests (exit code 5): the suite is missing, failing" >&2
  exit 1
fi
exit $rc
