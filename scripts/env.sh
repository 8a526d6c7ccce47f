# Source this file (do not execute it) to get a shell with everything the DAM suite needs:
#
#   source scripts/env.sh
#
# It sources /opt/ros/jazzy (when present and DAM_ROS is not "wheels"), activates the
# repository's virtual environment, puts the ROS 2 wheels installed there on the ament index
# (AMENT_PREFIX_PATH; wheels mode only), sources the workspace overlay ros2_ws/install and
# limits DDS discovery to this machine unless ROS_AUTOMATIC_DISCOVERY_RANGE is already set.
# It works in a caller running under `set -u` (the setup files it sources read unset
# variables, so `set -u` is off while they run and restored afterwards).
# Run scripts/setup.sh first.
# DAM_SYSTEM_ROS_PREFIX names the system ROS 2 install (default /opt/ros/jazzy), as in setup.sh.

_dam_root=$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")/.." && pwd)
case $- in
  *u*) _dam_nounset=1 ;;
  *) _dam_nounset=0 ;;
esac
set +u

if [ -f "${DAM_SYSTEM_ROS_PREFIX:-/opt/ros/jazzy}/setup.bash" ] &&
  [ "${DAM_ROS:-auto}" != wheels ]; then
  # shellcheck disable=SC1091
  source "${DAM_SYSTEM_ROS_PREFIX:-/opt/ros/jazzy}/setup.bash"
else
  # The ros-jazzy-* wheels install their ament index markers under <venv>/share/ament_index:
  # the venv is their prefix (setup.sh builds against it the same way).
  _dam_index="$_dam_root/.venv/share/ament_index/resource_index/packages"
  if [ -d "$_dam_index" ]; then
    case ":${AMENT_PREFIX_PATH:-}:" in
      *":$_dam_root/.venv:"*) ;;
      *) export AMENT_PREFIX_PATH="$_dam_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
    esac
  fi
  unset _dam_index
  # What a sourced Jazzy install sets, for the tools and code that ask (ros2 doctor, rosdep,
  # launch files, scripts testing ROS_DISTRO).
  export ROS_DISTRO=jazzy ROS_VERSION=2 ROS_PYTHON_VERSION=3
fi
if [ -f "$_dam_root/.venv/bin/activate" ]; then
  # shellcheck disable=SC1091
  source "$_dam_root/.venv/bin/activate"
else
  echo "env.sh: no virtual environment yet: run bash scripts/setup.sh" >&2
fi
if [ -f "$_dam_root/ros2_ws/install/setup.bash" ]; then
  # shellcheck disable=SC1091
  source "$_dam_root/ros2_ws/install/setup.bash"
else
  echo "env.sh: the workspace is not built yet: run bash scripts/setup.sh" >&2
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export DAM_REPO_ROOT="$_dam_root"

if [ "$_dam_nounset" = 1 ]; then
  set -u
fi
unset _dam_root _dam_nounset
