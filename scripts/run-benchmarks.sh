#!/usr/bin/env bash
# Run every bench/*.py with the project's venv; each prints a table and writes bench/results/<name>.json.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh
mkdir -p bench/results
for b in bench/*.py; do
  case "$(basename "$b")" in _*) continue ;; esac  # helper modules (sections, generators)
  echo "== $b"
  .venv/bin/python "$b" "$@"
done
.venv/bin/python scripts/update-readme-results.py
