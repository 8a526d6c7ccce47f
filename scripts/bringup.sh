#!/usr/bin/env bash
# Bring the DAM suite up in the background (plain shell, no launch files):
#   check_lift_server, hand_driver (which starts the PyBullet stand-in when no hand answers)
#   and spcm_controller.
#
#   bash scripts/bringup.sh [--backend auto|sim|hardware] [--gui] [--object NAME]
#   (NAME: an object of config/dam.yaml's object.library; the stand-in puts it on the table and
#   the controller classifies and checks for it; default object.default)
#   bash scripts/stop.sh          # stops exactly the processes started here, by PID
#
# Logs and PIDs go to $DAM_RUN_DIR (default: .run/ in the repository). Discovery stays on this
# machine unless ROS_AUTOMATIC_DISCOVERY_RANGE is set; ROS_DOMAIN_ID is taken from the caller.
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}

backend=auto
gui=false
object=""
while [ $# -gt 0 ]; do
  case "$1" in
    --backend) backend=${2:?--backend needs auto, sim or hardware}; shift 2 ;;
    --gui) gui=true; shift ;;
    --object) object=${2:?--object needs a name of object.library}; shift 2 ;;
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
    *) echo "bringup.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$backend" in auto|sim|hardware) ;; *)
  echo "bringup.sh: --backend must be auto, sim or hardware, got '$backend'" >&2; exit 2 ;;
esac

bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
mkdir -p "$RUN_DIR"

start() {  # start NAME PACKAGE EXECUTABLE [ARGS...]
  local name=$1 pkg=$2 exe=$3
  shift 3
  local pid_file="$RUN_DIR/$name.pid"
  if [ -f "$pid_file" ] && kill -0 "$(cat "$pid_file")" 2>/dev/null; then
    echo "    $name already running (PID $(cat "$pid_file"))"
    return 0
  fi
  local path="$REPO_ROOT/ros2_ws/install/$pkg/lib/$pkg/$exe"
  [ -x "$path" ] || { echo "bringup.sh: $pkg/$exe is not installed" >&2; exit 1; }
  PYTHONUNBUFFERED=1 nohup "$path" "$@" >"$RUN_DIR/$name.log" 2>&1 </dev/null &
  echo $! >"$pid_file"
  echo "    $name: PID $!, log $RUN_DIR/$name.log"
}

echo "==> Bringing up the DAM suite (ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}, backend $backend)"
start check_lift_server dam_analysis check_lift_server
# rcl refuses an empty override (-p object:=): the object only when one is named
object_args=()
[ -z "$object" ] || object_args=(-p "object:=$object")
start hand_driver dam_hand_driver hand_driver --ros-args -p "backend:=$backend" -p "gui:=$gui" \
  ${object_args[@]+"${object_args[@]}"}
start spcm_controller dam_spcm_controller spcm_controller --ros-args \
  ${object_args[@]+"${object_args[@]}"}
echo "ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}" >"$RUN_DIR/env"
sleep 1
for name in check_lift_server hand_driver spcm_controller; do
  if ! kill -0 "$(cat "$RUN_DIR/$name.pid")" 2>/dev/null; then
    echo "bringup.sh: $name exited at once; its log:" >&2
    tail -n 20 "$RUN_DIR/$name.log" >&2
    bash "$REPO_ROOT/scripts/stop.sh" >/dev/null || true
    exit 1
  fi
done
echo "==> Up. Stop with: bash scripts/stop.sh"
