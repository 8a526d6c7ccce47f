#!/usr/bin/env bash
# Make a stand-in for an apt-installed ROS 2 Jazzy (/opt/ros/jazzy) from the pinned PyPI wheels
# of scripts/requirements/ros-jazzy-wheels.txt, so that setup.sh's system-ROS path can run where
# no such install exists (CI on Debian):
#
#   bash scripts/lib/make_fake_system_ros.sh /tmp/jazzy
#   DAM_SYSTEM_ROS_PREFIX=/tmp/jazzy bash scripts/setup.sh
#
# The prefix is laid out as the apt packages lay out /opt/ros/jazzy:
#   setup.bash, local_setup.bash  set ROS_DISTRO=jazzy, ROS_VERSION=2, ROS_PYTHON_VERSION=3 and
#                                 put the prefix on AMENT_PREFIX_PATH, CMAKE_PREFIX_PATH,
#                                 PYTHONPATH, LD_LIBRARY_PATH and PATH (safe under `set -u`)
#   bin/                          executables
#   include/<pkg>/                headers
#   lib/                          every shared library, including those the wheels vendor in
#                                 site-packages/ros_*.libs (found through LD_LIBRARY_PATH, as on
#                                 a real install; the wheels' re-exec hook ros_wheels_bootstrapper
#                                 is removed)
#   lib/pythonX.Y/site-packages/  rclpy, the message packages, rosidl, ament; also numpy, scipy,
#                                 yaml, matplotlib and colcon, which a real system has from apt
#   share/<pkg>/, share/ament_index/resource_index/
# The wheels' CMake exports are repaired here (they name the wheel build machine's Python and
# numpy include directories), since on a real install they are right.
#
# PREFIX must not exist or be empty. DAM_PYTHON (default python3) is the Python the prefix is
# for: the system interpreter setup.sh will use, not a virtual environment's.
set -euo pipefail

REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
REQUIREMENTS="$REPO_ROOT/scripts/requirements/ros-jazzy-wheels.txt"

die() {
  printf 'make_fake_system_ros.sh: FAILED: %s\n' "$1" >&2
  if [ $# -gt 1 ]; then printf 'make_fake_system_ros.sh: what to do: %s\n' "$2" >&2; fi
  exit 1
}

[ $# = 1 ] || die "usage: bash scripts/lib/make_fake_system_ros.sh PREFIX" \
  "name one directory that does not exist yet (or is empty)"
mkdir -p "$1" || die "cannot create $1"
PREFIX=$(cd "$1" && pwd)
[ -z "$(ls -A "$PREFIX")" ] || die "$PREFIX is not empty" "name a new or empty directory"

PYTHON=${DAM_PYTHON:-python3}
command -v "$PYTHON" >/dev/null 2>&1 || die "no '$PYTHON' on PATH" "set DAM_PYTHON"
# The interpreter's real path (not a shim), its version, and its base if it is a venv's.
py_info=$("$PYTHON" -I -c '
import sys
base = getattr(sys, "_base_executable", sys.executable) if sys.prefix != sys.base_prefix else ""
print(sys.executable, "%d.%d" % sys.version_info[:2], base, sep="\n")
') || die "could not run $PYTHON"
{ read -r PY_EXE; read -r PY_VERSION; read -r PY_BASE || true; } <<<"$py_info"
[ -z "$PY_BASE" ] || die "$PY_EXE is a virtual environment's Python" \
  "a system ROS 2 belongs to the system Python: set DAM_PYTHON=$PY_BASE"
SITE="$PREFIX/lib/python$PY_VERSION/site-packages"

printf '==> pip install --prefix %s -r %s (Python %s)\n' "$PREFIX" \
  "${REQUIREMENTS#"$REPO_ROOT"/}" "$PY_VERSION"
# --ignore-installed: everything goes into the prefix, also what the interpreter already has;
# --no-warn-conflicts: the interpreter's own packages are no concern of the prefix.
# (Some pip configurations warn about every absent local index; keep the log readable.)
if ! env -u PYTHONPATH PIP_ROOT_USER_ACTION=ignore "$PY_EXE" -m pip install \
  --disable-pip-version-check -q --no-warn-script-location --no-warn-conflicts \
  --ignore-installed --prefix "$PREFIX" -r "$REQUIREMENTS" \
  2> >(grep -v "^WARNING: Location '.*' is ignored" >&2); then
  die "pip could not install the wheels into $PREFIX" \
    "check that the Python package index is reachable (pip config list; proxy settings)"
fi
[ -d "$SITE/rclpy" ] || die "pip put no rclpy into $SITE" \
  "look at where pip installed the packages (pip install --prefix layout of $PY_EXE)"

printf '==> Relocating what the wheels put elsewhere than the apt packages do\n'
"$PY_EXE" -I - "$PREFIX" "$SITE" <<'PYEOF' || die "could not lay out $PREFIX"
import filecmp
import pathlib
import shutil
import sys

prefix, site = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
lib = prefix / 'lib'

# auditwheel vendored the non-ROS libraries (tinyxml2, ssl, spdlog, ...) of each wheel into
# site-packages/ros_<wheel>.libs under hashed names; apt puts everything into lib/.
moved = 0
for libs_dir in sorted(site.glob('ros_*.libs')):
    for src in sorted(libs_dir.iterdir()):
        dst = lib / src.name
        if dst.exists():
            if not filecmp.cmp(src, dst, shallow=False):
                sys.exit(f'{src} and {dst} differ: cannot merge {libs_dir.name} into lib/')
        else:
            shutil.move(src, dst)
            moved += 1
    shutil.rmtree(libs_dir)
print(f'    moved {moved} vendored libraries from site-packages/ros_*.libs into lib/')

# The wheels' .pth hook re-executes Python with LD_LIBRARY_PATH; on a real install the
# environment comes from setup.bash.
removed = sorted(site.glob('ros_wheels_bootstrapper*'))
for path in removed:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink()
print(f'    removed the re-exec hook ({", ".join(p.name for p in removed) or "absent"})')

index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
for pkg in ('rclpy', 'std_msgs', 'rosidl_default_generators', 'ament_cmake'):
    if not (index / pkg).is_file() or not (prefix / 'share' / pkg / 'package.xml').is_file():
        sys.exit(f'{pkg} is not in the ament index or has no share/{pkg}/package.xml')
PYEOF

printf '==> Repairing the wheels'"'"' CMake exports\n'
env PYTHONPATH="$SITE" "$PY_EXE" "$REPO_ROOT/scripts/lib/repair_wheel_cmake.py" "$PREFIX" ||
  die "could not repair the CMake files under $PREFIX/share"

printf '==> Writing %s/setup.bash and local_setup.bash\n' "$PREFIX"
cat >"$PREFIX/local_setup.bash" <<EOF
# generated by scripts/lib/make_fake_system_ros.sh: the environment of this ROS 2 Jazzy prefix,
# as /opt/ros/jazzy/local_setup.bash sets it. Safe to source under \`set -u\` and twice.
_fake_ros_prefix=\$(builtin cd "\$(dirname "\${BASH_SOURCE[0]}")" >/dev/null && pwd)

# Put \$2 first on the colon-separated list named \$1 (once), and export it.
_fake_ros_prepend() {
  local value=":\${!1:-}:"
  while [[ \$value == *":\$2:"* ]]; do value=\${value//":\$2:"/:}; done
  value=\${value#:}
  value=\${value%:}
  export "\$1=\$2\${value:+:\$value}"
}

export ROS_DISTRO=jazzy ROS_VERSION=2 ROS_PYTHON_VERSION=3
_fake_ros_prepend AMENT_PREFIX_PATH "\$_fake_ros_prefix"
_fake_ros_prepend CMAKE_PREFIX_PATH "\$_fake_ros_prefix"
_fake_ros_prepend PYTHONPATH "\$_fake_ros_prefix/lib/python$PY_VERSION/site-packages"
_fake_ros_prepend LD_LIBRARY_PATH "\$_fake_ros_prefix/lib"
_fake_ros_prepend PATH "\$_fake_ros_prefix/bin"
unset -f _fake_ros_prepend
unset _fake_ros_prefix
EOF
cat >"$PREFIX/setup.bash" <<'EOF'
# generated by scripts/lib/make_fake_system_ros.sh: the environment of this ROS 2 Jazzy prefix
# (it has no underlay), as /opt/ros/jazzy/setup.bash sets it. Safe under `set -u`.
# shellcheck disable=SC1091
. "$(builtin cd "$(dirname "${BASH_SOURCE[0]}")" >/dev/null && pwd)/local_setup.bash"
EOF

printf '==> Checking the prefix in a clean environment\n'
# shellcheck disable=SC2016  # the single-quoted script expands its own arguments
env -u PYTHONPATH -u LD_LIBRARY_PATH -u AMENT_PREFIX_PATH -u CMAKE_PREFIX_PATH -u VIRTUAL_ENV \
  -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
  bash -c 'set -euo pipefail; source "$1/setup.bash"; exec "$2" -c "$3" "$1"' _ \
  "$PREFIX" "$PY_EXE" '
import os, sys
import colcon_core, matplotlib, numpy, scipy, yaml  # what a real system has from apt
import rclpy
from std_msgs.msg import String
prefix = sys.argv[1]
for mod in (rclpy, numpy, colcon_core):
    assert mod.__file__.startswith(prefix + "/lib/"), f"{mod.__name__} from {mod.__file__}"
rclpy.init()
rclpy.shutdown()
print("    rclpy", rclpy.__file__, "initialises; numpy", numpy.__version__)
' || die "the prefix does not work: rclpy, the messages or numpy/scipy/yaml/matplotlib/colcon" \
  "read the error above"
printf '==> Ready: DAM_SYSTEM_ROS_PREFIX=%s bash scripts/setup.sh\n' "$PREFIX"
