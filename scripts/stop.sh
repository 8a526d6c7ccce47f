#!/usr/bin/env bash
# Stop the processes scripts/bringup.sh started: by the PIDs it recorded, SIGINT first (clean
# shutdown, the driver stops its stand-in), SIGKILL after 10 s. Never by name.
set -uo pipefail
# A closed stdout (run.sh | head) must not stop it halfway, with processes left running.
trap '' PIPE
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RUN_DIR=${DAM_RUN_DIR:-$REPO_ROOT/.run}
shopt -s nullglob
stopped=0
# The recorder first (it closes its bag), the controller (it relaxes the hand), the driver last.
for name in recorder spcm_controller check_lift_server hand_driver; do
  pid_file="$RUN_DIR/$name.pid"
  [ -f "$pid_file" ] || continue
  pid=$(cat "$pid_file")
  # Only signal the PID if it still runs our executable (PIDs are reused).
  if kill -0 "$pid" 2>/dev/null && tr '\0' ' ' <"/proc/$pid/cmdline" | grep -q "/$name"; then
    kill -INT "$pid"
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$pid" 2>/dev/null; then
      echo "    $name (PID $pid) ignored SIGINT for 10 s: SIGKILL"
      kill -KILL "$pid"
    fi
    echo "    stopped $name (PID $pid)"
    stopped=$((stopped + 1))
  fi
  rm -f "$pid_file"
done
echo "==> stopped $stopped process(es)"
