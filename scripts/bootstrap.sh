#!/usr/bin/env bash
# Idempotent set-up of the development environment (no ROS apt repository needed):
#   1. .venv with pinned ROS 2 Jazzy wheels and Python dependencies (requirements.txt)
#   2. the CMake path fix for the wheels' exported targets (see docs/development.md)
#   3. colcon build of the interface package msg_defs/friction_msgs, installed into the venv prefix
#   4. friction_ros installed in editable mode so its entry points are on the venv PATH
# Every step is skipped when its inputs did not change, so a second run takes about a second.
# `bootstrap.sh --deps` does step 1 only.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
PY=${PYTHON:-python3}
STAMPS="$VENV/.friction_ros_stamps"

say() { printf '[bootstrap] %s\n' "$*"; }
hash_of() { cat "$@" | sha256sum | cut -d' ' -f1; }
stamp_ok() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV with $($PY --version)"
  "$PY" -m venv "$VENV"
fi
VPY="$VENV/bin/python"
SITE=$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')

# uv pip install -r requirements.txt with pip's indexes, find-links, constraints and certificate
# (uv does not read pip's configuration); pip's rule that every index is equal is kept.
uv_install() {
  local pin args=() key value
  pin=$(grep -ixE 'uv==[0-9.]+' requirements.txt) || return 1
  "$VPY" -m pip install --disable-pip-version-check -q --retries 1 --timeout 20 "$pin" || return 1
  while IFS='=' read -r key value; do
    value=${value#\'}; value=${value%\'}
    case "$key" in
      *.index-url) args+=(--index-url "$value") ;;
      *.extra-index-url) for v in $value; do args+=(--extra-index-url "$v"); done ;;
      *.find-links) for v in $value; do args+=(--find-links "$v"); done ;;
      *.constraint) for v in $value; do args+=(--constraint "$v"); done ;;
      *.cert) export SSL_CERT_FILE="$value" ;;
    esac
  done < <("$VPY" -m pip config list 2>/dev/null)
  "$VENV/bin/uv" pip install --python "$VPY" --index-strategy unsafe-best-match --compile-bytecode "${args[@]}" \
    -r requirements.txt
}

req_hash=$(hash_of requirements.txt)
if ! stamp_ok requirements "$req_hash"; then
  say "installing pinned dependencies (ROS 2 Jazzy wheels, numpy, scipy, python-can, mcap ...)"
  mkdir -p "$ROOT/build"
  # uv (pinned in requirements.txt) installs the same pins as pip, from the same indexes (pip's own
  # configuration), in parallel from its cache: 4 s instead of pip's 58 s here. Without uv (offline,
  # no wheel for this machine) pip does it.
  # Both byte-compile what they install (below: why it matters).
  if uv_install > build/pip-requirements.log 2>&1; then
    say "installed with uv $("$VENV/bin/uv" --version | cut -d' ' -f2)"
  else
    "$VPY" -m pip install --disable-pip-version-check -q -r requirements.txt > build/pip-requirements.log 2>&1 \
      || { grep -v '^WARNING: Location' build/pip-requirements.log | tail -20; say "pip install failed"; exit 1; }
  fi
  "$VPY" -c 'import rclpy, numpy, scipy, can, mcap' || { say "dependency install failed"; exit 1; }
  # The message wheels' exported CMake targets name include folders of the machine that built
  # them; point them at this venv's Python headers and numpy (reference: ros-jazzy-from-pip.md).
  PYINC=$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  NPINC=$("$VPY" -c 'import numpy; print(numpy.get_include())')
  grep -rlZ --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share" 2>/dev/null | xargs -0 -r sed -i \
    -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g" \
    -e "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g" || true
  stamp_set requirements "$req_hash"
  stamp_set bytecode "$req_hash"  # the install compiled them
  rm -f "$STAMPS/msgs" "$STAMPS/package"
fi

# --deps: stop here (the venv and its pinned dependencies; run-tests.sh compiles the numba kernels
# while the rest of the set-up runs)
[ "${1:-}" = "--deps" ] && exit 0

mkdir -p "$ROOT/build"
msg_hash=$(hash_of msg_defs/friction_msgs/package.xml msg_defs/friction_msgs/CMakeLists.txt msg_defs/friction_msgs/msg/*.msg)
if ! stamp_ok msgs "$msg_hash"; then
  say "building msg_defs/friction_msgs with colcon into the venv prefix"
  export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
  # Installed into the venv prefix: the ROS wheels' start-up hook already puts <venv>/lib on the
  # library path and <venv>/share on the ament index, so the messages import with no extra set-up.
  (cd "$ROOT" && PATH="$VENV/bin:$PATH" "$VENV/bin/colcon" --log-base build/colcon-log build \
     --base-paths msg_defs --build-base build/colcon --install-base "$VENV" --merge-install \
     --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VPY" \
     --event-handlers console_direct- summary+ > build/colcon-msgs.log 2>&1) \
    || { tail -40 build/colcon-msgs.log; say "colcon build of friction_msgs failed (log: build/colcon-msgs.log)"; exit 1; }
  "$VPY" -c 'from friction_msgs.msg import DriveState, FrictionEstimate, ControllerState, ExperimentEvent' \
    || { say "friction_msgs built but does not import"; exit 1; }
  stamp_set msgs "$msg_hash"
fi

pkg_hash=$(hash_of setup.py setup.cfg package.xml)
if ! stamp_ok package "$pkg_hash"; then
  say "installing friction_ros (editable) and its console scripts"
  "$VPY" -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation -e "$ROOT" \
    > build/pip-friction_ros.log 2>&1 || { tail -20 build/pip-friction_ros.log; say "pip install -e . failed"; exit 1; }
  (cd / && "$VPY" -c 'import friction_ros') || { say "friction_ros does not import"; exit 1; }
  # setup.cfg installs console scripts to <prefix>/lib/friction_ros (where `ros2 run` looks);
  # link them into the venv's bin so they are on PATH after `source .venv/bin/activate`.
  for exe in "$VENV"/lib/friction_ros/*; do [ -f "$exe" ] && ln -sf "$exe" "$VENV/bin/$(basename "$exe")"; done
  stamp_set package "$pkg_hash"
fi
# Byte-compiled dependencies and package: without .pyc files (uv writes none unless asked, and where
# PYTHONDONTWRITEBYTECODE is set Python never writes them) every process, each node and each test's
# graph, compiled scipy, numba and rclpy from source again: imports took 2.2 s instead of 1.1 s and
# a lockstep tracking run twice the CPU. The install compiles the dependencies; a venv installed
# before that is compiled here once (9 s); this package on every run (about 0.3 s when up to date).
if ! stamp_ok bytecode "$req_hash"; then
  say "byte-compiling the dependencies (once)"
  "$VPY" -m compileall -q -j 0 "$SITE" > build/compileall.log 2>&1 || true
  stamp_set bytecode "$req_hash"
fi
"$VPY" -m compileall -q -j 0 "$ROOT/friction_ros" "$SITE/friction_msgs" > /dev/null 2>&1 || true
say "ready: $VENV"
