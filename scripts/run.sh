#!/usr/bin/env bash
# The main job: bring the DAM suite up (on the PyBullet stand-in when no hand answers), ask
# /check_lift about the (k_theta, delta_theta_p) pair, grasp the object by Detaching Assist
# Motion through the /dam_grasp action, print the outcome, and stop everything it started.
# The grasp is recorded as an episode bag (bags/episodes/<time>_<outcome>, or under
# $DAM_BAG_DIR) and drawn (out/<episode>.png); the object's rise is printed, each figure once
# and named (the controller's estimate from the joints in the result line, the stand-in's
# measured rise under the recorded episode), and an episode bag the recorder marks incomplete
# is said to be so.
#
#   bash scripts/run.sh                                   # the pair configured in config/dam.yaml
#   bash scripts/run.sh --k-theta 0.5 --delta-theta-p 10deg   # any other pair
#   bash scripts/run.sh --backend hardware --keep         # a real hand; leave the suite running
#   bash scripts/run.sh --backend dynamixel               # Dynamixel servos: the emulated bus
#   bash scripts/run.sh --backend dynamixel --port /dev/ttyUSB0   # ... or a real one
#   bash scripts/run.sh --object square_bar               # another object of object.library
#   bash scripts/run.sh --params-file my_params.yaml      # parameters for the nodes
#   bash scripts/run.sh --timeout 300                     # give up if not up within 300 s
#   bash scripts/run.sh --ros-args -p spcm_controller:state_timeout:=0.2 --
#
# --params-file FILE (repeatable) and --ros-args ARGS [--] go to every node started here (the
# recorder included), as with scripts/bringup.sh: a parameter file keyed by node name
# (check_lift_server, hand_driver, spcm_controller, recorder; /**: for all), and
# node:name:=value for one node's parameter. --backend hardware with no hand answering fails
# within device.probe_timeout_s: no recorder, no goal, no bag.
#
# --timeout S (default $DAM_BRINGUP_TIMEOUT, else none) limits the bring-up and the
# recorder's start as in scripts/bringup.sh, and the clients' waits for their servers (the
# grasp's result: at least 120 s). Without it the nodes and the recorder are waited for while
# they progress, with a line every 10 s saying what each still waits for; the clients wait up
# to 300 s for a server and 1800 s for the grasp's result (a hang, not a slow machine).
#
# Exit status (the result line is printed whenever a grasp ran):
#   0  SUCCESS, and the episode bag is complete
#   1  the bring-up failed (a node or the recorder died while starting: its fatal line; the
#      probe refused), or no /dam_grasp action server answered; nothing is left running
#   2  bad arguments (a missing value, an unknown option or backend, a value out of range:
#      one line, refused before anything starts), or the controller refused the goal
#   3  another outcome (not lifted, lifted but not enveloped, aborted, cancelled)
#   4  gave up waiting for the bring-up or the recorder (--timeout, or nothing progressed
#      for 120 s)
#   5  the grasp ran but its episode bag is INCOMPLETE (the recorder's "... is INCOMPLETE"
#      line, custom data dam_episode.complete: "false"), or the recorder wrote no episode:
#      the outcome printed is not backed by a complete recording
#   130 Ctrl-C during the grasp: dam_grasp asked for a cancel while the nodes stop on the
#      same signal (its lines say how the goal ended); nothing is drawn; what run.sh started
#      is stopped (with --keep too)
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}
BAG_DIR=${DAM_BAG_DIR:-$REPO_ROOT/bags}

k_theta=""
delta_theta_p=""
backend=auto
port=""
keep=false
object=""
timeout=${DAM_BRINGUP_TIMEOUT:-none}
params=()    # the caller's --params-file FILE pairs, for every node
usage_error() { echo "run.sh: $1 (see --help)" >&2; exit 2; }
# need_value OPTION [VALUE ...] WHAT: OPTION must be followed by a value (not by another option)
need_value() {
  local what=${*: -1}
  [ $# -ge 3 ] && [ -n "$2" ] && [[ "$2" != --* ]] || usage_error "$1 needs $what"
}
ros_args=()  # the caller's --ros-args, for every node
seen_options=" "  # an option given twice is refused (docs/units.md); these may repeat:
while [ $# -gt 0 ]; do
  case "$1" in
    --params-file | --ros-args | -h | --help) ;;
    --*) [[ "$seen_options" != *" $1 "* ]] || usage_error "$1 given twice"
      seen_options+="$1 " ;;
  esac
  case "$1" in
    --params-file)
      [ $# -ge 2 ] || { echo "run.sh: --params-file needs a file (see --help)" >&2; exit 2; }
      [ -f "$2" ] || { echo "run.sh: --params-file: no such file '$2'" >&2; exit 2; }
      params+=(--params-file "$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"); shift 2 ;;
    --ros-args) shift
      while [ $# -gt 0 ] && [ "$1" != -- ]; do ros_args+=("$1"); shift; done
      [ $# -eq 0 ] || shift ;;
    --k-theta) need_value "$@" "a stiffness in N*m/rad"; k_theta=$2; shift 2 ;;
    --delta-theta-p) need_value "$@" "an angle (10deg)"; delta_theta_p=$2; shift 2 ;;
    --backend) need_value "$@" "auto, sim, hardware or dynamixel"; backend=$2; shift 2 ;;
    --port) need_value "$@" "a serial device (backend dynamixel)"; port=$2; shift 2 ;;
    --keep) keep=true; shift ;;
    --object) need_value "$@" "a name of object.library"; object=$2; shift 2 ;;
    --timeout) need_value "$@" "a number of seconds or none"; timeout=$2; shift 2 ;;
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
    *) usage_error "unknown argument '$1'" ;;
  esac
done
case "$backend" in auto|sim|hardware|dynamixel) ;; *)
  usage_error "--backend must be auto, sim, hardware or dynamixel, got '$backend'" ;;
esac
[ -z "$port" ] || [ "$backend" = dynamixel ] ||
  usage_error "--port is for --backend dynamixel (the UDP link's addresses are in device:)"

echo "==> Checking the workspace (the first run installs and builds it: a few minutes)"
bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u

# A name outside the library, or a pair the controller would refuse, is refused here, before
# anything starts. A bare angle is radians, as in every command (dam_common.quantities).
if [ -z "$k_theta" ] || [ -z "$delta_theta_p" ]; then
  read -r cfg_k cfg_dp < <(python -c '
import math
from dam_common.config import load_config
task = load_config().task
print(task.k_theta_nm_per_rad, repr(math.degrees(task.delta_theta_p_rad)) + "deg")')
  k_theta=${k_theta:-$cfg_k}
  delta_theta_p=${delta_theta_p:-$cfg_dp}
fi
DAM_RUN_OBJECT=$object DAM_RUN_K=$k_theta DAM_RUN_DP=$delta_theta_p python -c '
import argparse, os, sys
from dam_common.config import load_config
from dam_common.errors import ConfigError
from dam_common.quantities import ANGLE, argument, number_argument
try:
    config = load_config().with_object(os.environ["DAM_RUN_OBJECT"])
except ConfigError as exc:
    sys.exit(f"run.sh: --object: {exc}")
dp_max = config.task.delta_theta_p_max_rad
for option, parse, text in (
        ("--k-theta", number_argument(above=0.0, unit="N*m/rad", what="stiffness"),
         os.environ["DAM_RUN_K"]),
        ("--delta-theta-p", argument(ANGLE, low=0.0, low_inclusive=False, high=dp_max),
         os.environ["DAM_RUN_DP"])):
    try:
        value = parse(text)
    except argparse.ArgumentTypeError as exc:
        sys.exit(f"run.sh: {option}: {exc}")' || exit 2

[ "$timeout" = none ] || { [[ "$timeout" =~ ^[0-9]+([.][0-9]+)?$ ]] &&
  [[ "$timeout" =~ [1-9] ]]; } || {
  echo "run.sh: --timeout must be a positive number of seconds or none, got '$timeout'" >&2
  exit 2; }

bringup_args=(--backend "$backend" --timeout "$timeout" ${params[@]+"${params[@]}"})
[ -z "$port" ] || bringup_args+=(--port "$port")
[ -z "$object" ] || bringup_args+=(--object "$object")
[ ${#ros_args[@]} -eq 0 ] || bringup_args+=(--ros-args "${ros_args[@]}" --)
# bringup.sh returns when every node serves; when it fails it has stopped what it started.
up=0
bash "$REPO_ROOT/scripts/bringup.sh" "${bringup_args[@]}" || up=$?
case "$up" in 0) ;; 2|4) exit "$up" ;; *) exit 1 ;; esac
exe() { echo "$REPO_ROOT/ros2_ws/install/$1/lib/$1/$2"; }

# The recorder, in episode mode: this grasp becomes one bag.
recorder_log="$RUN_DIR/recorder.log"
recorder_ros=(--ros-args)  # the clock bringup.sh chose, then the caller's parameters
if [ "$(sed -n 's/^DAM_SIM_TIME=//p' "$RUN_DIR/env")" = true ]; then
  recorder_ros+=(-p use_sim_time:=true)
fi
recorder_ros+=(${params[@]+"${params[@]}"} ${ros_args[@]+"${ros_args[@]}"} --)
PYTHONUNBUFFERED=1 "$(exe dam_recorder recorder)" --episodes -o "$BAG_DIR/episodes" \
  "${recorder_ros[@]}" >"$recorder_log" 2>&1 </dev/null &
recorder_pid=$!
echo "$recorder_pid" >"$RUN_DIR/recorder.pid"
stop_recorder() {
  if kill -0 "$recorder_pid" 2>/dev/null; then
    kill -INT "$recorder_pid"
    wait "$recorder_pid" 2>/dev/null || true
  fi
  rm -f "$RUN_DIR/recorder.pid"
}
if [ "$keep" != true ]; then
  trap 'stop_recorder; bash "$REPO_ROOT/scripts/stop.sh"' EXIT
else
  trap 'stop_recorder' EXIT
fi
echo "    recorder: PID $recorder_pid, log $recorder_log"
# The recorder follows the controller's goals and the hand's topics before the goal is sent:
# waited for as the nodes are (while it progresses, or up to --timeout).
ready=0
python "$REPO_ROOT/scripts/lib/wait_ready.py" --who run.sh --timeout "$timeout" \
  "recorder=$recorder_pid:$recorder_log" || ready=$?
case "$ready" in 0) ;; 2) exit 4 ;; *) exit 1 ;; esac
# A device stream that stalled while everything started (a busy machine) leaves the driver in
# ERROR; its ~/reset brings it back (it answers 'already ACTIVE' otherwise).
python - <<'PY' || true
import rclpy
from std_srvs.srv import Trigger
rclpy.init()
node = rclpy.create_node('run_sh_reset')
client = node.create_client(Trigger, '/hand_driver/reset')
if client.wait_for_service(timeout_sec=10.0):
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
    if future.result() is not None and future.result().message != 'already ACTIVE':
        print(f'    driver reset: {future.result().message}')
node.destroy_node()
rclpy.shutdown()
PY
# The clients' own waits (discovery, the answer): --timeout when given, else generous ones
# (a client that starts on a loaded machine discovers the servers slowly; a grasp on the
# stand-in's clock may take minutes of wall time there).
if [ "$timeout" = none ]; then client_wait=300; result_wait=1800; else
  client_wait=$timeout; result_wait=$(awk -v t="$timeout" 'BEGIN { print (t > 120 ? t : 120) }'); fi
echo "==> /check_lift for k_theta = $k_theta N*m/rad, delta_theta_p = $delta_theta_p"
"$(exe dam_analysis check_lift)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --object "$object" --timeout "$client_wait" || true
echo "==> DAM grasp"
grasp_log="$RUN_DIR/dam_grasp.log"
# The result line's message carries the controller's estimate of the rise ('rise 9.75 mm
# (estimated from the joints)'): dam_grasp's next line, the same estimate again ('object rise:
# 9.7 mm, left the table (estimated from the joint angles)'), stays in its log only. Read line
# by line as each comes (a pipe into awk would hold the phases back until the end).
without_second_estimate() {
  local line estimate=false
  while IFS= read -r line || [ -n "$line" ]; do
    case $line in
      'result: '*'(estimated from the joints)'*) estimate=true ;;
      'result: '*) estimate=false ;;
      'object rise: '*'(estimated from the joint angles)')
        [ "$estimate" = true ] && continue ;;
    esac
    printf '%s\n' "$line"
  done
}
# Ctrl-C reaches dam_grasp, which cancels the goal and prints its result; tee and the filter
# ignore it so that those lines are shown and logged. The nodes stop on it too: nothing is
# drawn then, and run.sh exits with 130 once everything it started has stopped.
interrupted=false
trap 'interrupted=true' INT
set +e
"$(exe dam_spcm_controller dam_grasp)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --server-timeout "$client_wait" --timeout "$result_wait" 2>&1 |
  (trap '' INT; tee "$grasp_log") | (trap '' INT; without_second_estimate)
status=${PIPESTATUS[0]}
set -e
trap - INT
if [ "$interrupted" = true ]; then
  echo "run.sh: interrupted (Ctrl-C) during the grasp: dam_grasp asked for a cancel while the" \
    "nodes stop on the same signal (its lines above say how the goal ended); nothing is" \
    "drawn (exit status 130)" >&2
  exit 130
fi

# The episode closes after its post-roll; then the recorder is stopped and the grasp drawn.
# A recorder behind a busy machine catches up first: waited for while it runs and its episode
# bags grow, until they have not grown for 60 s.
episode=""
bags_size=""
still=0
looks=0
while :; do
  episode=$(sed -n 's/.*\] \[recorder\]: episode [A-Z_]*: //p' "$recorder_log" | tail -n 1)
  [ -n "$episode" ] && break
  kill -0 "$recorder_pid" 2>/dev/null || break
  size=$(du -sb "$BAG_DIR/episodes" 2>/dev/null | cut -f1) || size=""
  if [ "$size" != "$bags_size" ]; then bags_size=$size; still=0; else still=$((still + 1)); fi
  [ "$still" -lt 120 ] || break
  looks=$((looks + 1))
  [ $((looks % 20)) -ne 0 ] ||
    echo "    waiting $((looks / 2)) s for the recorder to close the episode (post-roll)"
  sleep 0.5
done
stop_recorder
incomplete=false
if [ -z "$episode" ]; then
  incomplete=true
  echo "run.sh: the recorder wrote no episode (log: $recorder_log)" >&2
else
  mkdir -p "$REPO_ROOT/out"
  picture="$REPO_ROOT/out/$(basename "$episode").png"
  echo "==> Recorded"
  echo "    bag:     $episode"
  if [ "$(python "$REPO_ROOT/scripts/lib/episode_complete.py" "$episode")" = false ] ||
      grep -qF "$(basename "$episode") is INCOMPLETE" "$recorder_log"; then
    incomplete=true
    echo "    INCOMPLETE: the recorder marked this episode bag incomplete (messages of the" \
      "grasp are missing; see $recorder_log)"
  fi
  plot=$("$(exe dam_recorder bag)" plot "$episode" -o "$picture") ||
    echo "run.sh: bag plot $episode failed" >&2
  # bag plot's object lines, each naming its source (the stand-in's ground truth; the
  # controller's estimate, or 'none recorded'), without the figures the result line above
  # already gives: each rise once (scripts/lib/object_summary.py).
  summary=$(python "$REPO_ROOT/scripts/lib/object_summary.py" "$grasp_log" <<<"$plot") &&
    plot=$summary
  [ -z "$plot" ] || sed 's/^/    /' <<<"$plot"
  echo "    picture: $picture"
fi
# A grasp that ran (0 or 3) whose recording is not complete has a status of its own.
if [ "$incomplete" = true ] && { [ "$status" = 0 ] || [ "$status" = 3 ]; }; then
  echo "run.sh: exit status 5: the episode bag is INCOMPLETE or missing; the outcome above" \
    "(client status $status) is not backed by a complete recording" >&2
  status=5
fi
exit "$status"
