#!/usr/bin/env bash
# Stop the processes scripts/bringup.sh started: by the PIDs it recorded, SIGINT first (clean
# shutdown, the driver stops its stand-in), SIGKILL after 10 s. Never by name. The recorder
# first, then the controller and the analysis server together, the driver last.
set -uo pipefail
# A closed stdout (run.sh | head) must not stop it halfway, with processes left running.
trap '' PIPE
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}
shopt -s nullglob
stopped=0
ours() {  # ours NAME: the PID of NAME started here, if it still runs our executable
  local pid_file="$RUN_DIR/$1.pid" pid
  [ -f "$pid_file" ] || return 1
  pid=$(cat "$pid_file")
  # Only signal the PID if it still runs our executable (PIDs are reused).
  kill -0 "$pid" 2>/dev/null && tr '\0' ' ' <"/proc/$pid/cmdline" | grep -q "/$1" && echo "$pid"
}
stop_stage() {  # stop_stage NAME...: SIGINT to each, then wait for all of them together
  local name pid names=() pids=()
  for name in "$@"; do
    if pid=$(ours "$name"); then
      kill -INT "$pid"
      names+=("$name")
      pids+=("$pid")
    fi
  done
  for _ in $(seq 100); do
    local alive=0
    for pid in ${pids[@]+"${pids[@]}"}; do kill -0 "$pid" 2>/dev/null && alive=1; done
    [ "$alive" = 1 ] || break
    sleep 0.1
  done
  local i
  for i in ${pids[@]+"${!pids[@]}"}; do
    if kill -0 "${pids[$i]}" 2>/dev/null; then
      echo "    ${names[$i]} (PID ${pids[$i]}) ignored SIGINT for 10 s: SIGKILL"
      kill -KILL "${pids[$i]}"
    fi
    echo "    stopped ${names[$i]} (PID ${pids[$i]})"
    stopped=$((stopped + 1))
  done
  for name in "$@"; do rm -f "$RUN_DIR/$name.pid"; done
}
# The recorder first (it closes its bag), then the controller (it relaxes the hand) together
# with the analysis server and the /tf publishers (independent of both), the driver last.
stop_stage recorder
stop_stage spcm_controller check_lift_server dam_state_publisher robot_state_publisher
stop_stage hand_driver
noun=processes
[ "$stopped" -ne 1 ] || noun=process
echo "==> stopped $stopped $noun"
