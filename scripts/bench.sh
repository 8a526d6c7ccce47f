#!/usr/bin/env bash
# Run the benchmarks in bench/ (all, or those named): bash scripts/bench.sh [check_lift ...]
# Options: --quick (fewer samples), --grid (sweep: also the 480-trial grid and the parallel
# efficiency against its bare-physics ceiling, ~15 minutes).
#
# Each benchmark measures its target and a baseline in the same run and reports the ratio;
# results are printed and written as JSON to bench/results/ (not tracked by git).
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/lib/ros_domain.sh"
dam_reserve_ros_domain
echo "==> Benchmarks (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, discovery $ROS_AUTOMATIC_DISCOVERY_RANGE)"
cd "$REPO_ROOT"
exec python bench/run.py "$@"
