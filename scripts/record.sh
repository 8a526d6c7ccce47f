#!/usr/bin/env bash
# Record beside a scripts/bringup.sh session until stopped (Ctrl-C or SIGTERM closes the bag).
#
#   bash scripts/record.sh                      # the default topics into bags/rosbag2_<time>
#   bash scripts/record.sh --episodes           # one bag per /dam_grasp goal, in bags/episodes
#   bash scripts/record.sh -o DIR [recorder options and topics]   # see: recorder --help
#
# Without -o the bag goes under $DAM_BAG_DIR (default: bags/ in the repository). The
# ROS_DOMAIN_ID is the caller's, else the one bringup.sh used. When that bring-up runs on the
# stand-in, the recorder gets -p use_sim_time:=true (the stand-in's /clock), before any
# --ros-args of the caller (which win). The recorder runs in the foreground (exec): its exit
# status is this script's.
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}
BAG_DIR=${DAM_BAG_DIR:-$REPO_ROOT/bags}

episodes=false
output_given=false
for arg in "$@"; do
  case "$arg" in
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
    --episodes) episodes=true ;;
    -o|--output|--output=*) output_given=true ;;
  esac
done

bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
if [ -z "${ROS_DOMAIN_ID:-}" ] && [ -f "$RUN_DIR/env" ]; then
  # shellcheck disable=SC1091
  source "$RUN_DIR/env"
  export ROS_DOMAIN_ID
fi

args=("$@")
if [ -f "$RUN_DIR/env" ] && [ "$(sed -n 's/^DAM_SIM_TIME=//p' "$RUN_DIR/env")" = true ]; then
  args=(--ros-args -p use_sim_time:=true -- "${args[@]}")
fi
if [ "$output_given" = false ]; then
  mkdir -p "$BAG_DIR"
  if [ "$episodes" = true ]; then
    args=(-o "$BAG_DIR/episodes" "${args[@]}")
  else
    args=(-o "$BAG_DIR/rosbag2_$(date +%Y_%m_%d-%H_%M_%S)" "${args[@]}")
  fi
fi
echo "==> Recording (ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}); Ctrl-C stops and closes the bag" >&2
PYTHONUNBUFFERED=1 exec "$REPO_ROOT/ros2_ws/install/dam_recorder/lib/dam_recorder/recorder" \
  "${args[@]}"
