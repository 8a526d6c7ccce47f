#!/usr/bin/env bash
# The main job: bring the DAM suite up (on the PyBullet stand-in when no hand answers), ask
# /check_lift about the (k_theta, delta_theta_p) pair, grasp the object by Detaching Assist
# Motion through the /dam_grasp action, print the outcome, and stop everything it started.
# The grasp is recorded as an episode bag (bags/episodes/<time>_<outcome>, or under
# $DAM_BAG_DIR) and drawn (out/<episode>.png); the object's rise is printed, with where the
# number comes from, and an episode bag the recorder marks incomplete is said to be so.
#
#   bash scripts/run.sh                                   # the pair configured in config/dam.yaml
#   bash scripts/run.sh --k-theta 0.5 --delta-theta-p 10deg   # any other pair
#   bash scripts/run.sh --backend hardware --keep         # a real hand; leave the suite running
#   bash scripts/run.sh --backend dynamixel               # Dynamixel servos: the emulated bus
#   bash scripts/run.sh --backend dynamixel --port /dev/ttyUSB0   # ... or a real one
#   bash scripts/run.sh --object square_bar               # another object of object.library
#   bash scripts/run.sh --params-file my_params.yaml      # parameters for the nodes
#   bash scripts/run.sh --ros-args -p spcm_controller:state_timeout:=0.2 --
#
# --params-file FILE (repeatable) and --ros-args ARGS [--] go to every node started here (the
# recorder included), as with scripts/bringup.sh: a parameter file keyed by node name
# (check_lift_server, hand_driver, spcm_controller, recorder; /**: for all), and
# node:name:=value for one node's parameter. --backend hardware with no hand answering fails
# within device.probe_timeout_s: no recorder, no goal, no bag.
#
# Exit status: that of the grasp client (0 success, 3 another outcome, 2 rejected, 1 no answer);
# 1 when the bring-up failed (nothing is left running).
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
params=()    # the caller's --params-file FILE pairs, for every node
ros_args=()  # the caller's --ros-args, for every node
while [ $# -gt 0 ]; do
  case "$1" in
    --params-file)
      [ $# -ge 2 ] || { echo "run.sh: --params-file needs a file (see --help)" >&2; exit 2; }
      [ -f "$2" ] || { echo "run.sh: --params-file: no such file '$2'" >&2; exit 2; }
      params+=(--params-file "$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"); shift 2 ;;
    --ros-args) shift
      while [ $# -gt 0 ] && [ "$1" != -- ]; do ros_args+=("$1"); shift; done
      [ $# -eq 0 ] || shift ;;
    --k-theta) k_theta=${2:?--k-theta needs a value}; shift 2 ;;
    --delta-theta-p) delta_theta_p=${2:?--delta-theta-p needs a value}; shift 2 ;;
    --backend) backend=${2:?--backend needs auto, sim, hardware or dynamixel}; shift 2 ;;
    --port) port=${2:?--port needs a serial device (backend dynamixel)}; shift 2 ;;
    --keep) keep=true; shift ;;
    --object) object=${2:?--object needs a name of object.library}; shift 2 ;;
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
    *) echo "run.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

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
        ("--k-theta", number_argument(low=0.0, unit="N*m/rad"), os.environ["DAM_RUN_K"]),
        ("--delta-theta-p", argument(ANGLE, low=0.0, low_inclusive=False, high=dp_max),
         os.environ["DAM_RUN_DP"])):
    try:
        value = parse(text)
    except argparse.ArgumentTypeError as exc:
        sys.exit(f"run.sh: {option}: {exc}")
    if option == "--k-theta" and value <= 0.0:
        sys.exit(f"run.sh: --k-theta: {text!r} must be a positive stiffness [N*m/rad]")' || exit 2

bringup_args=(--backend "$backend" ${params[@]+"${params[@]}"})
[ -z "$port" ] || bringup_args+=(--port "$port")
[ -z "$object" ] || bringup_args+=(--object "$object")
[ ${#ros_args[@]} -eq 0 ] || bringup_args+=(--ros-args "${ros_args[@]}" --)
# bringup.sh returns when every node serves; when it fails it has stopped what it started.
bash "$REPO_ROOT/scripts/bringup.sh" "${bringup_args[@]}" || exit 1
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
for _ in $(seq 300); do  # the recorder follows the controller's goals and the hand's topics
  if grep -q 'recording /dam/episode ' "$recorder_log" \
      && grep -q 'recording /joint_states ' "$recorder_log"; then break; fi
  kill -0 "$recorder_pid" 2>/dev/null || { cat "$recorder_log" >&2; exit 1; }
  sleep 0.1
done
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
echo "==> /check_lift for k_theta = $k_theta N*m/rad, delta_theta_p = $delta_theta_p"
"$(exe dam_analysis check_lift)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --object "$object" --timeout 30 || true
echo "==> DAM grasp"
grasp_log="$RUN_DIR/dam_grasp.log"
set +e
"$(exe dam_spcm_controller dam_grasp)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --server-timeout 30 2>&1 | tee "$grasp_log"
status=${PIPESTATUS[0]}
set -e
# The controller's own estimate of the rise (from the joint angles), when its client prints it.
rise_from_result=false
grep -q 'object rise: .*(estimated from the joint angles)' "$grasp_log" &&
  rise_from_result=true

# The episode closes after its post-roll; then the recorder is stopped and the grasp drawn.
episode=""
for _ in $(seq 600); do  # up to 60 s: a recorder behind a busy machine catches up first
  episode=$(sed -n 's/.*\] \[recorder\]: episode [A-Z_]*: //p' "$recorder_log" | tail -n 1)
  [ -n "$episode" ] && break
  sleep 0.1
done
stop_recorder
if [ -z "$episode" ]; then
  echo "run.sh: the recorder wrote no episode (log: $recorder_log)" >&2
else
  mkdir -p "$REPO_ROOT/out"
  picture="$REPO_ROOT/out/$(basename "$episode").png"
  echo "==> Recorded"
  echo "    bag:     $episode"
  if [ "$(python "$REPO_ROOT/scripts/lib/episode_complete.py" "$episode")" = false ]; then
    echo "    INCOMPLETE: the recorder marked this episode bag incomplete (messages of the" \
      "grasp are missing; see $recorder_log)"
  fi
  plot=$("$(exe dam_recorder bag)" plot "$episode" -o "$picture") ||
    echo "run.sh: bag plot $episode failed" >&2
  if [ "$rise_from_result" = true ]; then
    # The controller's result says the rise; the bag's ground truth would be a second number.
    plot=$(grep -v 'object rise' <<<"$plot" || true)
  elif grep -q 'object rise' <<<"$plot"; then
    plot+=$'\n'"  (that rise is the stand-in's ground truth recorded in the bag,"
    plot+=" /sim/object_pose; the controller does not report its own estimate yet)"
  fi
  [ -z "$plot" ] || sed 's/^/    /' <<<"$plot"
  echo "    picture: $picture"
fi
exit "$status"
