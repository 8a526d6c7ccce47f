#!/usr/bin/env bash
# The results document: run the Fig. 7 sweep (resumable; a finished sweep is not run again)
# and generate docs/results.md from it, with its figures in docs/results/ (not tracked); the
# document's section 6 calibrates the CSM on the sweep (calibrate_csm, docs/analysis.md).
#
#   bash scripts/results.sh                    # the sweep of docs/results.md into sweeps/fig7
#   bash scripts/results.sh --workers 1        # extra arguments go to `sweep`
#
# Environment: DAM_SWEEP_DIR (default sweeps/fig7), DAM_RESULTS (default docs/results.md).
# The grid: friction angles 5 and 30 deg, k_theta 0.05-20 N*m/rad (20 log-spaced values),
# delta_theta_p 5-60 deg (12 values): 480 whole grasps, about 10 minutes on two cores.
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
case "${1:-}" in
  -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
esac
# Paths relative to the repository: the document quotes the commands that made it.
SWEEP_DIR=${DAM_SWEEP_DIR:-sweeps/fig7}
RESULTS=${DAM_RESULTS:-docs/results.md}

bash "$REPO_ROOT/scripts/setup.sh" >/dev/null
set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
cd "$REPO_ROOT"
mkdir -p "$(dirname "$SWEEP_DIR")"
bin=ros2_ws/install/dam_experiments/lib/dam_experiments
"$bin/sweep" --friction-angles 5deg 30deg --k-theta 0.05:20:20:log --delta-theta-p 5deg:60deg:12 \
  --config config/dam.yaml --out "$SWEEP_DIR" "$@"
"$bin/sweep_report" "$SWEEP_DIR" -o "$RESULTS" --config config/dam.yaml --calibrate
