#!/usr/bin/env bash
# Rewrite requirements.txt from the current .venv: every installed distribution pinned, except
# friction_ros itself and the egg-info distributions bundled inside the ROS wheels (they are not
# installable on their own).
set -euo pipefail
cd "$(dirname "$0")/.."
SITE=$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
bundled=$(cd "$SITE" && ls -d *.egg-info 2>/dev/null | sed -E 's/-[0-9][^-]*-py3\.[0-9]+\.egg-info$//' | tr 'A-Z_.' 'a-z--')
{
  echo "# Pinned environment of friction_ros: ROS 2 Jazzy wheels from PyPI + Python dependencies."
  echo "# Regenerate with scripts/freeze-requirements.sh after changing what is installed."
  .venv/bin/pip freeze --all --exclude-editable | grep -v -iE "^(friction|-e |pip==|setuptools==)" | while read -r line; do
    name=$(echo "${line%%==*}" | tr 'A-Z_.' 'a-z--')
    grep -qx "$name" <<<"$bundled" || echo "$line"
  done
} > requirements.txt
echo "requirements.txt: $(grep -vc '^#' requirements.txt) pins"
