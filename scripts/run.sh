#!/usr/bin/env bash
# The main job: bring the DAM suite up (on the PyBullet stand-in when no hand answers), ask
# /check_lift about the (k_theta, delta_theta_p) pair, grasp the cylinder by Detaching Assist
# Motion through the /dam_grasp action, print the outcome, and stop everything it started.
#
#   bash scripts/run.sh                                   # the pair configured in config/dam.yaml
#   bash scripts/run.sh --k-theta 0.5 --delta-theta-p 10deg   # any other pair
#   bash scripts/run.sh --backend hardware --keep         # a real hand; leave the suite running
#
# Exit status: that of the grasp client (0 success, 3 another outcome, 2 rejected, 1 no answer).
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

k_theta=""
delta_theta_p=""
backend=auto
keep=false
while [ $# -gt 0 ]; do
  case "$1" in
    --k-theta) k_theta=${2:?--k-theta needs a value}; shift 2 ;;
    --delta-theta-p) delta_theta_p=${2:?--delta-theta-p needs a value}; shift 2 ;;
    --backend) backend=${2:?--backend needs auto, sim or hardware}; shift 2 ;;
    --keep) keep=true; shift ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    *) echo "run.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u

if [ -z "$k_theta" ] || [ -z "$delta_theta_p" ]; then
  read -r cfg_k cfg_dp < <(python -c '
import math
from dam_common.config import load_config
task = load_config().task
print(task.k_theta_nm_per_rad, repr(math.degrees(task.delta_theta_p_rad)) + "deg")')
  k_theta=${k_theta:-$cfg_k}
  delta_theta_p=${delta_theta_p:-$cfg_dp}
fi

bash "$REPO_ROOT/scripts/bringup.sh" --backend "$backend"
if [ "$keep" != true ]; then
  trap 'bash "$REPO_ROOT/scripts/stop.sh"' EXIT
fi

exe() { echo "$REPO_ROOT/ros2_ws/install/$1/lib/$1/$2"; }
echo "==> /check_lift for k_theta = $k_theta N*m/rad, delta_theta_p = $delta_theta_p"
"$(exe dam_analysis check_lift)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --timeout 30 || true
echo "==> DAM grasp"
set +e
"$(exe dam_spcm_controller dam_grasp)" --k-theta "$k_theta" --delta-theta-p "$delta_theta_p" \
  --server-timeout 30
status=$?
set -e
exit "$status"
