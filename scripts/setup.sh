#!/usr/bin/env bash
# Set up everything the DAM suite needs and build the colcon workspace. Idempotent: a second
# run with nothing changed only checks and returns.
#
#   bash scripts/setup.sh            # use /opt/ros/jazzy if present, else ROS 2 wheels from PyPI
#   DAM_ROS=wheels bash scripts/setup.sh   # force the PyPI wheels even where /opt/ros/jazzy exists
#   DAM_FORCE_BUILD=1 bash scripts/setup.sh  # rebuild even if no source changed
#   DAM_SYSTEM_ROS_PREFIX=/path/to/jazzy bash scripts/setup.sh  # a system ROS 2 Jazzy elsewhere
#
# Every other script calls this first. It installs what is missing (apt as root, pip into a
# virtual environment inside the repository), then runs `colcon build` into ros2_ws/install.
# With a system ROS 2 Jazzy (DAM_SYSTEM_ROS_PREFIX, default /opt/ros/jazzy, holds setup.bash)
# it sources that setup.bash first, creates the venv with --system-site-packages and installs
# only the extra Python packages into it. Setting DAM_SYSTEM_ROS_PREFIX to a directory without
# setup.bash is an error (unless DAM_ROS=wheels).
set -euo pipefail

REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV="$REPO_ROOT/.venv"
WS="$REPO_ROOT/ros2_ws"
REQ_DIR="$REPO_ROOT/scripts/requirements"
SYSTEM_ROS_PREFIX=${DAM_SYSTEM_ROS_PREFIX:-/opt/ros/jazzy}
SYSTEM_ROS_SETUP="$SYSTEM_ROS_PREFIX/setup.bash"

step() { printf '==> %s\n' "$*"; }
info() { printf '    %s\n' "$*"; }
# pip's output as one line per package it collects, downloads, builds or installs, each with
# the seconds since the step began: pip itself is silent for minutes with -q, and its progress
# bars need a terminal.
pip_progress() {
  local line t0=$SECONDS n=0
  while IFS= read -r line; do
    case "$line" in
      Collecting\ *)
        n=$((n + 1))
        printf '    [%4d s] collecting %s (%d)\n' "$((SECONDS - t0))" "${line#Collecting }" "$n" ;;
      *Downloading\ *)
        printf '    [%4d s]   downloading %s\n' "$((SECONDS - t0))" "${line##*Downloading }" ;;
      *"Building wheel for "*)
        printf '    [%4d s]   building %s\n' "$((SECONDS - t0))" "${line##*Building wheel for }" ;;
      "Installing collected packages: "*)
        set -- ${line#Installing collected packages: }
        printf '    [%4d s] installing %d packages (no output until they are in)\n' \
          "$((SECONDS - t0))" "$#" ;;
      "Successfully installed "*)
        set -- ${line#Successfully installed }
        printf '    [%4d s] installed %d packages\n' "$((SECONDS - t0))" "$#" ;;
    esac
  done
}
# colcon's start and end of each package, with its time, while the full output goes to a log.
colcon_progress() {
  local line
  while IFS= read -r line; do
    printf '%s\n' "$line" >>"$1"
    case "$line" in
      "Starting >>> "* | "Finished <<< "* | "Failed   <<< "* | "Aborted  <<< "*)
        printf '    %s\n' "$line" ;;
    esac
  done
}
die() {
  printf 'setup.sh: FAILED: %s\n' "$1" >&2
  if [ $# -gt 1 ]; then printf 'setup.sh: what to do: %s\n' "$2" >&2; fi
  exit 1
}

# ------------------------------------------------------------------------------------------
step "Checking Python"
PYTHON=${DAM_PYTHON:-python3}
command -v "$PYTHON" >/dev/null 2>&1 ||
  die "no '$PYTHON' on PATH" "install Python 3.11 or newer (apt-get install python3)"
if ! "$PYTHON" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)'; then
  die "$("$PYTHON" --version 2>&1) is too old: ROS 2 Jazzy here needs Python 3.11 or newer" \
    "install Python 3.11+ and run again with DAM_PYTHON=/path/to/python3.11"
fi
PY_VERSION=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
info "$("$PYTHON" --version 2>&1)"

if [ -f "$SYSTEM_ROS_SETUP" ] && [ "${DAM_ROS:-auto}" != wheels ]; then
  MODE=system
  info "ROS 2: system install at $SYSTEM_ROS_PREFIX"
  # Everything below (the Python package checks, pip, colcon) sees the system ROS 2, as in a
  # shell where its setup.bash is sourced. It may read unset variables.
  set +u
  # shellcheck disable=SC1090
  source "$SYSTEM_ROS_SETUP" || die "sourcing $SYSTEM_ROS_SETUP failed" \
    "check that it is a ROS 2 Jazzy install, or set DAM_ROS=wheels to use the PyPI wheels"
  set -u
elif [ -n "${DAM_SYSTEM_ROS_PREFIX:-}" ] && [ "${DAM_ROS:-auto}" != wheels ]; then
  die "DAM_SYSTEM_ROS_PREFIX=$DAM_SYSTEM_ROS_PREFIX has no setup.bash" \
    "point it at a ROS 2 Jazzy install (the directory holding setup.bash), or unset it"
else
  MODE=wheels
  info "ROS 2: Jazzy wheels from PyPI into $VENV"
fi

# ------------------------------------------------------------------------------------------
step "Checking system tools"
missing_apt=()
command -v cc >/dev/null 2>&1 || missing_apt+=(gcc)
command -v c++ >/dev/null 2>&1 || missing_apt+=(g++)
command -v make >/dev/null 2>&1 || missing_apt+=(make)
command -v cmake >/dev/null 2>&1 || missing_apt+=(cmake)
if [ ! -x "$VENV/bin/python" ] && ! "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1; then
  missing_apt+=("python${PY_VERSION}-venv")
fi
if [ "$MODE" = system ]; then
  # The system message packages are built against the distribution's numpy: use its packages.
  for mod_pkg in numpy:python3-numpy scipy:python3-scipy yaml:python3-yaml \
    matplotlib:python3-matplotlib colcon_core:python3-colcon-common-extensions; do
    "$PYTHON" -c "import ${mod_pkg%%:*}" >/dev/null 2>&1 || missing_apt+=("${mod_pkg#*:}")
  done
fi
if [ ${#missing_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    info "installing with apt-get: ${missing_apt[*]}"
    apt-get update -qq >/dev/null ||
      die "apt-get update failed" "check that a Debian/Ubuntu package mirror is reachable"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing_apt[@]}" >/dev/null ||
      die "apt-get install ${missing_apt[*]} failed" "run it by hand to see why"
  else
    die "missing system packages: ${missing_apt[*]}" \
      "sudo apt-get install ${missing_apt[*]}   (then run this script again)"
  fi
else
  info "compiler, cmake and venv are present"
fi

# ------------------------------------------------------------------------------------------
step "Python virtual environment ($VENV)"
if [ ! -x "$VENV/bin/python" ]; then
  if [ "$MODE" = system ]; then
    "$PYTHON" -m venv --system-site-packages "$VENV" || die "could not create $VENV"
  else
    "$PYTHON" -m venv "$VENV" || die "could not create $VENV"
  fi
  info "created"
else
  info "present"
fi
VPY="$VENV/bin/python"

req_files=("$REQ_DIR/python.txt")
[ "$MODE" = wheels ] && req_files=("$REQ_DIR/ros-jazzy-wheels.txt" "${req_files[@]}")
req_hash=$(cat "${req_files[@]}" | sha1sum | cut -d' ' -f1)-$MODE
req_stamp="$VENV/.dam-requirements"
if [ "$(cat "$req_stamp" 2>/dev/null)" != "$req_hash" ]; then
  pip_args=(-m pip install --disable-pip-version-check --progress-bar off)
  constraints=()
  if [ "$MODE" = system ]; then
    # Never replace the distribution's numpy inside the venv (ABI of the message packages).
    sys_numpy=$("$PYTHON" -c 'import numpy; print(numpy.__version__)')
    printf 'numpy==%s\n' "$sys_numpy" >"$VENV/.dam-constraints.txt"
    constraints=(-c "$VENV/.dam-constraints.txt")
  fi
  # Measured on a 2-core machine: the whole setup takes about 2 minutes when idle, about 9
  # beside 13 busy processes; nearly all of it is pip.
  info "installing the pinned packages: about 2 minutes on an idle machine, several times" \
    "that on a busy one (pip's progress below)"
  for req in "${req_files[@]}"; do
    info "pip install -r ${req#"$REPO_ROOT"/}"
    # (Some pip configurations warn about every absent local index; keep the log readable.)
    if ! "$VPY" "${pip_args[@]}" -r "$req" "${constraints[@]}" \
      2> >(grep -v "^WARNING: Location '.*' is ignored" >&2) | pip_progress; then
      die "pip could not install ${req#"$REPO_ROOT"/}" \
        "check that the Python package index is reachable (pip config list; proxy settings)"
    fi
  done
  echo "$req_hash" >"$req_stamp"
  rm -f "$VENV/.dam-cmake-repaired"
else
  info "pinned requirements already installed"
fi

# ------------------------------------------------------------------------------------------
if [ "$MODE" = wheels ]; then
  step "Repairing the wheels' CMake exports"
  if [ ! -f "$VENV/.dam-cmake-repaired" ]; then
    # The wheels' exported CMake files name the wheel build machine's Python and numpy
    # include directories; point them at this venv's.
    "$VPY" "$REPO_ROOT/scripts/lib/repair_wheel_cmake.py" "$VENV" ||
      die "could not repair the CMake files under $VENV/share"
    touch "$VENV/.dam-cmake-repaired"
  else
    info "already repaired"
  fi
fi

# ------------------------------------------------------------------------------------------
step "Building the workspace ($WS)"
# Rebuild only when a source, the config or the environment (which ROS 2) changed.
ros_source=$MODE
if [ "$MODE" = system ]; then ros_source="system $SYSTEM_ROS_PREFIX"; fi
src_hash=$(
  cd "$REPO_ROOT" &&
    { find src interfaces config -type f ! -name '*.pyc' ! -path '*/__pycache__/*' \
      -printf '%p %s %T@\n' |
      sort; echo "$ros_source $req_hash"; } | sha1sum | cut -d' ' -f1
)
build_stamp="$WS/install/.dam-source-hash"
if [ "${DAM_FORCE_BUILD:-0}" != 1 ] && [ "$(cat "$build_stamp" 2>/dev/null)" = "$src_hash" ]; then
  info "up to date (no change in src/ or config/)"
else
  set +u
  # shellcheck disable=SC1091
  source "$VENV/bin/activate"
  set -u
  if [ "$MODE" = wheels ]; then
    export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
  fi
  command -v colcon >/dev/null 2>&1 ||
    die "colcon is not installed" "apt-get install python3-colcon-common-extensions"
  mkdir -p "$WS/log"
  cd "$WS"
  # interfaces/: standard ROS 2 messages the PyPI wheels lack (tf2_msgs/msg/TFMessage for /tf
  # and /tf_static), built only where the ROS 2 underneath has no such package.
  base_paths=("$REPO_ROOT/src")
  if [ ! -f "$SYSTEM_ROS_PREFIX/share/tf2_msgs/package.xml" ] || [ "$MODE" = wheels ]; then
    base_paths+=("$REPO_ROOT/interfaces")
  fi
  n_packages=$(find "${base_paths[@]}" -mindepth 2 -maxdepth 2 -name package.xml | wc -l)
  info "colcon build, $n_packages packages, a line as each starts and ends" \
    "(log: $WS/log/latest_build)"
  : >"$WS/log/colcon-output.txt"
  if ! colcon --log-base "$WS/log" build --base-paths "${base_paths[@]}" \
    --build-base "$WS/build" --install-base "$WS/install" \
    --event-handlers console_start_end+ console_cohesion- summary+ status- \
    --cmake-args -DPython3_EXECUTABLE="$VPY" -DBUILD_TESTING=OFF 2>&1 |
    colcon_progress "$WS/log/colcon-output.txt"
  then
    tail -n 30 "$WS/log/colcon-output.txt" >&2 || true
    die "colcon build failed" \
      "read $WS/log/colcon-output.txt and $WS/log/latest_build/<package>/stdout_stderr.log"
  fi
  grep -E '^Summary' "$WS/log/colcon-output.txt" | sed 's/^/    /' || true
  echo "$src_hash" >"$build_stamp"
fi

step "Ready. Use it with:  source scripts/env.sh"
