#!/usr/bin/env bash
# Bring the DAM suite up in the background (plain shell, no launch files):
#   check_lift_server, hand_driver (which starts the PyBullet stand-in when no hand answers),
#   spcm_controller and dam_state_publisher (/tf and /tf_static of the hand and the object).
#   Returns when every node serves, or fails (non-zero) with the fatal line of the node that
#   died, after stopping what it started. No fixed limit decides how
#   long the nodes may take on a loaded machine: it waits while they progress.
#
#   bash scripts/bringup.sh [--backend auto|sim|hardware|dynamixel] [--port DEV] [--gui]
#                           [--object NAME] [--timeout S] [--params-file FILE]...
#                           [--state-publisher dam|system|none]
#                           [--ros-args ARGS... [--]]
#   bash scripts/stop.sh          # stops exactly the processes started here, by PID
#
#   --backend   auto (default): probe the device link for device.probe_timeout_s; a hand that
#               answers is driven as hardware, else the stand-in runs (simulated time).
#               sim: always the stand-in. hardware: a hand must answer within the probe time,
#               else nothing starts (exit 1). dynamixel: Dynamixel servos on a serial bus
#               (docs/dynamixel.md): --port DEV or dynamixel.port; with neither, the driver
#               starts the emulated bus (the PyBullet stand-in as nine servos, simulated time).
#   --port      the Dynamixel bus's serial device, e.g. /dev/ttyUSB0 (--backend dynamixel)
#   --gui       open the stand-in's PyBullet window (needs a display)
#   --object    an object of config/dam.yaml's object.library (default object.default)
#   --timeout S give up when the nodes are not ready S seconds after their start [s]
#               (default $DAM_BRINGUP_TIMEOUT, else none: wait while they progress)
#   --state-publisher    who publishes the hand's frames on /tf and /tf_static: dam (default)
#               dam_state_publisher, the suite's own (the hand from /robot_description and
#               /joint_states, the stand-in's object as the frame 'object'); system: the real
#               robot_state_publisher of a system ROS 2 Jazzy (apt's
#               ros-jazzy-robot-state-publisher) for the hand, dam_state_publisher for the
#               object only; none: no /tf at all
#   --params-file FILE   a ROS 2 parameter file for every node started (keys: the node name,
#               e.g. spcm_controller: or hand_driver:, or /**: for all nodes); repeatable
#   --ros-args ARGS [--] ROS arguments for every node started, e.g.
#               --ros-args -p spcm_controller:state_timeout:=0.2 -p hand_driver:thread_priority:=0
#               (node:name:=value sets one node's parameter; name:=value every node's)
#
# Ready means: /check_lift answers, the /dam_grasp action server is up, /joint_states is
# published and the driver reports ACTIVE on /diagnostics. While a node is not ready and its
# process runs, bring-up waits as long as something progresses (a new log line of a node not
# ready, CPU time of a node that has printed nothing yet or of the driver's stand-in, one more
# condition met, a new node, topic or service in the graph) and says every 10 s what each node
# still waits for ("check_lift_server: up 20 s, CPU 1.2 s: no log line yet"). It gives up
# when --timeout passes, or when nothing progressed for 120 s (a node that hangs).
#
# Exit status: 0 every node serves; 1 a node died while starting (its [FATAL] lines, else its
# last lines, are printed at once), the device probe refused, or a bring-up still runs;
# 2 bad arguments; 4 gave up waiting (--timeout, or nothing progressed for 120 s), naming
# what is still missing. On 1 and 4 what was started is stopped.
#
# With the stand-in every node gets -p use_sim_time:=true (the stand-in is the clock); with a
# real hand none does. Parameters given here come after the script's own, so they win.
#
# Logs and PIDs go to $DAM_RUN_DIR (default: .run/ in the repository). Discovery stays on this
# machine unless ROS_AUTOMATIC_DISCOVERY_RANGE is set; ROS_DOMAIN_ID is taken from the caller.
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}
NODES=(check_lift_server hand_driver spcm_controller dam_state_publisher robot_state_publisher)

usage_error() { echo "bringup.sh: $1 (see --help)" >&2; exit 2; }
backend=auto
port=""
gui=false
object=""
timeout=${DAM_BRINGUP_TIMEOUT:-none}
state_publisher=dam
user_args=()  # --params-file and --ros-args of the caller, for every node
seen_options=" "  # an option given twice is refused (docs/units.md); these may repeat:
while [ $# -gt 0 ]; do
  case "$1" in
    --params-file | --ros-args | -h | --help) ;;
    --*) [[ "$seen_options" != *" $1 "* ]] || usage_error "$1 given twice"
      seen_options+="$1 " ;;
  esac
  case "$1" in
    --backend) [ $# -ge 2 ] || usage_error "--backend needs auto, sim, hardware or dynamixel"
      backend=$2; shift 2 ;;
    --port) [ $# -ge 2 ] || usage_error "--port needs a serial device (backend dynamixel)"
      port=$2; shift 2 ;;
    --gui) gui=true; shift ;;
    --object) [ $# -ge 2 ] || usage_error "--object needs a name of object.library"
      object=$2; shift 2 ;;
    --state-publisher) [ $# -ge 2 ] || usage_error "--state-publisher needs dam, system or none"
      state_publisher=$2; shift 2 ;;
    --timeout) [ $# -ge 2 ] || usage_error "--timeout needs a number of seconds or none"
      timeout=$2; shift 2 ;;
    --params-file) [ $# -ge 2 ] || usage_error "--params-file needs a file"
      [ -f "$2" ] || usage_error "--params-file: no such file '$2'"
      user_args+=(--params-file "$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"); shift 2 ;;
    --ros-args) shift
      while [ $# -gt 0 ] && [ "$1" != -- ]; do user_args+=("$1"); shift; done
      [ $# -eq 0 ] || shift ;;
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
    *) usage_error "unknown argument '$1'" ;;
  esac
done
case "$state_publisher" in dam|system|none) ;; *)
  usage_error "--state-publisher must be dam, system or none, got '$state_publisher'" ;;
esac
case "$backend" in auto|sim|hardware|dynamixel) ;; *)
  usage_error "--backend must be auto, sim, hardware or dynamixel, got '$backend'" ;;
esac
[ -z "$port" ] || [ "$backend" = dynamixel ] ||
  usage_error "--port is for --backend dynamixel (the UDP link's addresses are in device:)"
[ -z "$port" ] || [ -e "$port" ] || usage_error "--port: no such device '$port'"
[ "$timeout" = none ] || { [[ "$timeout" =~ ^[0-9]+([.][0-9]+)?$ ]] &&
  [[ "$timeout" =~ [1-9] ]]; } ||
  usage_error "--timeout must be a positive number of seconds or none, got '$timeout'"

bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
mkdir -p "$RUN_DIR"
rsp_exe=""
if [ "$state_publisher" = system ]; then
  rsp_exe=$(python -c 'from ament_index_python.packages import get_package_prefix as p
print(p("robot_state_publisher") + "/lib/robot_state_publisher/robot_state_publisher")' \
    2>/dev/null) && [ -x "$rsp_exe" ] || usage_error "--state-publisher system: no" \
    "robot_state_publisher in this ROS 2 (apt-get install ros-jazzy-robot-state-publisher;" \
    "the PyPI wheels have none: use --state-publisher dam)"
fi

running() {  # running NAME: the PID of NAME started by an earlier bring-up, if it still runs
  local pid_file="$RUN_DIR/$1.pid" pid
  [ -f "$pid_file" ] || return 1
  pid=$(cat "$pid_file")
  kill -0 "$pid" 2>/dev/null && tr '\0' ' ' <"/proc/$pid/cmdline" 2>/dev/null | grep -q "/$1" &&
    echo "$pid"
}
for name in "${NODES[@]}"; do
  if pid=$(running "$name"); then
    echo "bringup.sh: $name is already running (PID $pid, log $RUN_DIR/$name.log);" \
      "stop it first: bash scripts/stop.sh" >&2
    exit 1
  fi
done

echo "==> Bringing up the DAM suite (ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}, backend $backend)"
# Which device answers decides the driver's backend and whose clock the nodes follow: the
# probe binds the state port and closes it before the driver binds it.
driver_backend=$backend
sim_time=true
if [ "$backend" = dynamixel ]; then
  # A port (here or dynamixel.port): a real bus, wall-clock time; none: the emulated bus the
  # driver starts, which is the clock.
  [ -n "$port" ] || port=$(python -c 'from dam_common.config import load_config
c = load_config()
print(c.dynamixel.port if c.dynamixel is not None else "")') || {
    echo "bringup.sh: the configuration cannot be read; nothing started" >&2; exit 1; }
  if [ -n "$port" ]; then
    sim_time=false
    echo "    Dynamixel bus on $port"
  else
    echo "    no Dynamixel port configured: the driver starts the emulated bus"
  fi
elif [ "$backend" != sim ]; then
  probe=$(python "$REPO_ROOT/scripts/lib/probe_device.py") || {
    echo "bringup.sh: the device probe failed; nothing started" >&2; exit 1; }
  kind=${probe%%$'\t'*}
  echo "    probe: ${probe#*$'\t'}"
  case "$backend:$kind" in
    *:hardware) driver_backend=hardware; sim_time=false ;;
    auto:simulated) driver_backend=auto ;;
    auto:nothing) driver_backend=sim ;;
    hardware:simulated)
      echo "bringup.sh: --backend hardware: ${probe#*$'\t'}, not a hand; nothing started" \
        "(--backend auto drives it)" >&2
      exit 1 ;;
    hardware:nothing)
      echo "bringup.sh: --backend hardware: ${probe#*$'\t'} (device.probe_timeout_s);" \
        "nothing started" >&2
      exit 1 ;;
    *) echo "bringup.sh: the device probe said '$probe'" >&2; exit 1 ;;
  esac
fi
common=()
[ "$sim_time" = false ] || common=(-p use_sim_time:=true)
echo "    driver backend $driver_backend, $([ "$sim_time" = true ] &&
  echo "simulated time (use_sim_time:=true)" || echo "wall-clock time")"
printf 'ROS_DOMAIN_ID=%s\nDAM_SIM_TIME=%s\n' "${ROS_DOMAIN_ID:-0}" "$sim_time" >"$RUN_DIR/env"

start() {  # start NAME PACKAGE EXECUTABLE [ROS ARGS...]: in the background, PID to NAME.pid
  local name=$1 pkg=$2 exe=$3
  shift 3
  local path="$REPO_ROOT/ros2_ws/install/$pkg/lib/$pkg/$exe"
  [ -x "$path" ] || { echo "bringup.sh: $pkg/$exe is not installed" >&2; exit 1; }
  PYTHONUNBUFFERED=1 nohup "$path" --ros-args ${common[@]+"${common[@]}"} "$@" \
    ${user_args[@]+"${user_args[@]}"} >"$RUN_DIR/$name.log" 2>&1 </dev/null &
  echo $! >"$RUN_DIR/$name.pid"
  echo "    $name: PID $!, log $RUN_DIR/$name.log"
}
# From here on a failure stops what was started.
trap 'echo "bringup.sh: stopping what it started" >&2;
      bash "$REPO_ROOT/scripts/stop.sh" >&2 || true' EXIT
# rcl refuses an empty override (-p object:=): the object only when one is named
object_args=()
[ -z "$object" ] || object_args=(-p "object:=$object")
start check_lift_server dam_analysis check_lift_server
port_args=()
[ -z "$port" ] || port_args=(-p "port:=$port")
start hand_driver dam_hand_driver hand_driver -p "backend:=$driver_backend" -p "gui:=$gui" \
  ${object_args[@]+"${object_args[@]}"} ${port_args[@]+"${port_args[@]}"}
start spcm_controller dam_spcm_controller spcm_controller ${object_args[@]+"${object_args[@]}"}
case "$state_publisher" in
  dam) start dam_state_publisher dam_hand_driver dam_state_publisher ;;
  system)
    # the real robot_state_publisher takes the URDF as a parameter, from a file
    python - "$RUN_DIR/robot_state_publisher.yaml" <<'PY'
import sys

import yaml

from dam_common.config import load_config
from dam_common.hand_urdf import hand_urdf

with open(sys.argv[1], 'w', encoding='utf-8') as f:
    yaml.safe_dump({'robot_state_publisher': {'ros__parameters': {
        'robot_description': hand_urdf(load_config())}}}, f)
PY
    PYTHONUNBUFFERED=1 nohup "$rsp_exe" --ros-args ${common[@]+"${common[@]}"} \
      --params-file "$RUN_DIR/robot_state_publisher.yaml" \
      ${user_args[@]+"${user_args[@]}"} >"$RUN_DIR/robot_state_publisher.log" 2>&1 </dev/null &
    echo $! >"$RUN_DIR/robot_state_publisher.pid"
    echo "    robot_state_publisher: PID $!, log $RUN_DIR/robot_state_publisher.log"
    start dam_state_publisher dam_hand_driver dam_state_publisher -p robot_state:=false ;;
esac

watch=()
watched=(check_lift_server hand_driver spcm_controller)
[ "$state_publisher" = none ] || watched+=(dam_state_publisher)
for name in "${watched[@]}"; do
  watch+=("$name=$(cat "$RUN_DIR/$name.pid"):$RUN_DIR/$name.log")
done
if [ "$timeout" = none ]; then
  echo "==> Waiting until every node serves (while they progress; --timeout S sets a limit)"
else
  echo "==> Waiting until every node serves (up to $timeout s)"
fi
ready=0
python "$REPO_ROOT/scripts/lib/wait_ready.py" --who bringup.sh --timeout "$timeout" \
  "${watch[@]}" || ready=$?
case "$ready" in
  0) ;;
  2) exit 4 ;;  # gave up waiting
  *) exit 1 ;;
esac
trap - EXIT
echo "==> Up. Stop with: bash scripts/stop.sh"
