#!/usr/bin/env bash
# One idempotent set-up for a fresh machine: Debian packages for headless rendering, the Python
# virtual environment with pinned ROS 2 Jazzy wheels, and a colcon build of zeus_msgs + zeus_ros.
# Re-running it only redoes what changed (stamp files), so `make test` and `make demo` call it.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
say() { printf '[setup] %s\n' "$*"; }

# 1. Debian packages: Mesa EGL/OSMesa for offscreen MuJoCo rendering.
APT_PACKAGES=(libegl1 libgl1 libegl-mesa0 libgles2 libosmesa6)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if ((${#missing[@]})); then
  if [ "$(id -u)" -eq 0 ]; then
    say "installing Debian packages: ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  elif command -v sudo >/dev/null; then
    sudo apt-get update -qq
    sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    say "missing Debian packages ${missing[*]} and no root: install them, then re-run" >&2
    exit 1
  fi
fi

# 2. Python 3.11 virtual environment (the ROS Jazzy wheels are cp311).
PYTHON=${PYTHON:-}
if [ -z "$PYTHON" ]; then
  for candidate in python3.11 python3; do
    if command -v "$candidate" >/dev/null && \
       "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      PYTHON=$(command -v "$candidate"); break
    fi
  done
fi
if [ -z "$PYTHON" ]; then
  say "Python 3.11 not found (the ROS 2 Jazzy wheels are built for CPython 3.11)" >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV with $PYTHON"
  "$PYTHON" -m venv "$VENV"
fi
REQ_HASH=$(sha256sum requirements.txt | cut -d' ' -f1)
if [ "$(cat "$VENV/.requirements.sha256" 2>/dev/null)" != "$REQ_HASH" ]; then
  say "installing pinned Python packages (first run: a few minutes)"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -r requirements.txt
  echo "$REQ_HASH" > "$VENV/.requirements.sha256"
fi

# 3. The Jazzy wheels' exported CMake targets name the include dirs of the machine they were built
#    on (/opt/python/cp311-cp311/...); point them at this interpreter and numpy.
PY_INCLUDE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
NP_INCLUDE=$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')
{ grep -rlZ --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share" 2>/dev/null || true; } | \
  xargs -0 -r sed -i \
    -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NP_INCLUDE#g" \
    -e "s#/opt/python/cp311-cp311/include/python3.11#$PY_INCLUDE#g"

# 4. colcon build of the interface package and the Python package, as a ROS user would.
# shellcheck source=/dev/null
source "$VENV/bin/activate"
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
export LD_LIBRARY_PATH="$VENV/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
mkdir -p "$ROOT/log"
# The build is skipped when nothing it reads changed since the last good one (a stamp in
# install/ holding scripts/build_inputs.sh's hash): a second `make demo` starts at once.
STAMP="$ROOT/install/.zeus-build-inputs.sha256"
INPUTS="$(bash "$ROOT/scripts/build_inputs.sh" "$ROOT") $REQ_HASH $VENV"  # + the interpreter
built() {
  [ "$(cat "$STAMP" 2>/dev/null)" = "$INPUTS" ] && [ -f "$ROOT/install/setup.bash" ] && \
    [ -d "$ROOT/install/zeus_msgs" ] && [ -d "$ROOT/install/zeus_ros" ] && \
    [ -z "$(find "$ROOT/install/zeus_ros" -xtype l -print -quit)" ]
}
if built; then
  say "colcon build up to date (zeus_msgs, zeus_ros: no input changed since the last build)"
else
  # A symlink install keeps links to files the tree no longer has (a moved params file fails the
  # build: "can't copy ... not a regular file"), and installed data files that setup.py stopped
  # listing (the research checkpoints before the zoo): drop both, colcon lays the rest anew.
  for stale in "$ROOT/build/zeus_ros" "$ROOT/install/zeus_ros"; do
    [ -d "$stale" ] && find "$stale" -xtype l -delete
  done
  rm -rf "$ROOT/install/zeus_ros/share/zeus_ros/checkpoints"
  rm -f "$STAMP"
  say "colcon build (zeus_msgs, zeus_ros)"
  colcon --log-base "$ROOT/log" build --base-paths "$ROOT" "$ROOT/msg_defs" \
    --build-base "$ROOT/build" --install-base "$ROOT/install" --symlink-install \
    --event-handlers console_cohesion- summary+ status- \
    --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF \
    > "$ROOT/log/colcon-build.txt" 2>&1 || {
      tail -n 60 "$ROOT/log/colcon-build.txt" >&2
      say "colcon build failed: full log in log/colcon-build.txt" >&2
      exit 1
    }
  echo "$INPUTS" > "$STAMP"
fi
say "ready: source scripts/env.sh to use zeus_ros in this shell"
