#!/usr/bin/env bash
# Run the whole test suite: set up and build (scripts/setup.sh), then pytest over tests/.
#
#   bash scripts/test.sh                 # everything: unit tests (with the system-ROS setup
#                                        # test beside them), then the integration tests
#   bash scripts/test.sh -k config -x    # extra arguments go to pytest
#   bash scripts/test.sh tests/dam_common -q   # only these paths (they replace the default)
#
# Each run reserves its own ROS_DOMAIN_ID (a lock file per id), so parallel runs on one
# machine never see each other's nodes; discovery stays on this machine (LOCALHOST).
set -euo pipefail
REPO_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

bash "$REPO_ROOT/scripts/setup.sh"

set +u
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/env.sh"
set -u
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

# Reserve a domain id nobody else on this machine is using for the length of this run.
# shellcheck disable=SC1091
source "$REPO_ROOT/scripts/lib/ros_domain.sh"
dam_reserve_ros_domain
echo "==> Running tests (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, discovery $ROS_AUTOMATIC_DISCOVERY_RANGE)"

cd "$REPO_ROOT"
# Test paths given on the command line replace the default set (every test).
paths_given=false
for arg in "$@"; do
  case "$arg" in
    -*) ;;
    *) if [ -e "${arg%%::*}" ]; then paths_given=true; fi ;;
  esac
done
run_pytest() {  # pytest with the common options; its exit status (5: no test collected)
  python -m pytest -p no:cacheprovider -ra -rR "$@"  # R: why a rerun test failed first
}
set +e
if [ "$paths_given" = true ]; then
  run_pytest "$@"
  status=$?
  [ "$status" = 5 ] && { echo "test.sh: pytest collected no tests" >&2; exit 1; }
  exit "$status"
fi

# Every test, in two phases (each prints pytest's summary line):
# 1. the unit tests (pure cores, installed executables without DDS timing) on every core,
#    while the system-ROS setup test (two pip installs and a build in a copy) runs beside them;
# 2. the integration tests over DDS with real-time nodes, one at a time.
system_ros=tests/integration/test_system_ros_setup.py
# Unit tests that measure real time wait for phase 2 (the build beside phase 1 takes the CPU).
realtime_unit=(
  tests/dam_sim_bridge/test_pacing.py::test_real_time_state_frames_are_stamped_one_period_apart_and_sent_on_time
)
unit=(tests/dam_* tests/integration/test_package_layout.py tests/integration/test_env_script.py)
for pkg_tests in src/*/test; do
  if [ -d "$pkg_tests" ]; then unit+=("$pkg_tests"); fi
done
echo "==> Phase 1: unit tests, and $system_ros beside them"
system_ros_log=$(mktemp)
run_pytest "$system_ros" "$@" >"$system_ros_log" 2>&1 &
system_ros_pid=$!
deselect=()
for t in "${realtime_unit[@]}"; do deselect+=(--deselect "$t"); done
# The unit tests on every core (pytest-xdist); those that talk DDS in the test process share
# one worker (--dist loadgroup), so they never see each other's topics.
workers=$(nproc 2>/dev/null || echo 2)
run_pytest -n "$workers" --dist loadgroup "${unit[@]}" "${deselect[@]}" "$@"
unit_status=$?
wait "$system_ros_pid"
system_ros_status=$?
cat "$system_ros_log"
rm -f "$system_ros_log"
echo "==> Phase 2: integration tests"
integration=()
for t in tests/integration/test_*.py; do
  case " ${unit[*]} $system_ros " in *" $t "*) ;; *) integration+=("$t") ;; esac
done
run_pytest --durations=12 "${realtime_unit[@]}" "${integration[@]}" "$@"
integration_status=$?
set -e
status=0
collected=0
for s in "$unit_status" "$system_ros_status" "$integration_status"; do
  case "$s" in
    0) collected=1 ;;
    5) ;;
    *) collected=1; status=1 ;;
  esac
done
if [ "$collected" = 0 ]; then
  echo "test.sh: pytest collected no tests" >&2
  exit 1
fi
exit "$status"
