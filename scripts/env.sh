# Source this file (do not execute it) to get a shell with everything the DAM suite needs:
#
#   source scripts/env.sh
#
# It sources /opt/ros/jazzy (when present and DAM_ROS is not "wheels"), activates the
# repository's virtual environment, sources the workspace overlay ros2_ws/install and limits
# DDS discovery to this machine unless ROS_AUTOMATIC_DISCOVERY_RANGE is already set.
# Run scripts/setup.sh first.
# DAM_SYSTEM_ROS_PREFIX names the system ROS 2 install (default /opt/ros/jazzy), as in setup.sh.

_dam_root=$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")/.." && pwd)

if [ -f "${DAM_SYSTEM_ROS_PREFIX:-/opt/ros/jazzy}/setup.bash" ] &&
  [ "${DAM_ROS:-auto}" != wheels ]; then
  # shellcheck disable=SC1091
  source "${DAM_SYSTEM_ROS_PREFIX:-/opt/ros/jazzy}/setup.bash"
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
unset _dam_root
