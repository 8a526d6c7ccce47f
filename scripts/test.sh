#!/usr/bin/env bash
# Run the whole test suite: set up and build (scripts/setup.sh), then pytest over tests/.
#
#   bash scripts/test.sh                 # everything: unit tests (with the system-ROS setup
#                                        # test beside them), then the integration tests
#   bash scripts/test.sh -k config -x    # extra arguments go to pytest
#   bash scripts/test.sh tests/dam_common -q   # only these paths (they replace the default)
#   bash scripts/test.sh --quick         # the quick tier for development: the unit tests only
#                                        # (about 2.5 minutes on 2 cores; no DDS timing, no
#                                        # system-ROS setup)
#
# The integration tests run on DAM_TEST_WORKERS processes side by side (default 2), each
# on a domain and UDP ports of its own, a whole test file per process.
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
quick=false
args=()
for arg in "$@"; do
  if [ "$arg" = --quick ]; then quick=true; else args+=("$arg"); fi
done
set -- ${args[@]+"${args[@]}"}
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
# 2. the integration tests over DDS with real-time nodes, two test files at a time (each
#    worker on a ROS_DOMAIN_ID and UDP ports of its own), then those that load the machine
#    (marker exclusive: six CPU burners, storms of driver starts) alone.
system_ros=tests/integration/test_system_ros_setup.py
# Unit tests that measure real time wait for phase 2 (the build beside phase 1 takes the CPU).
realtime_unit=(
  tests/dam_sim_bridge/test_pacing.py::test_real_time_state_frames_are_stamped_one_period_apart_and_sent_on_time
)
unit=(tests/dam_* tests/integration/test_package_layout.py tests/integration/test_env_script.py)
for pkg_tests in src/*/test; do
  if [ -d "$pkg_tests" ]; then unit+=("$pkg_tests"); fi
done
deselect=()
for t in "${realtime_unit[@]}"; do deselect+=(--deselect "$t"); done
# The unit tests on every core (pytest-xdist); those that talk DDS in the test process share
# one worker (--dist loadgroup), so they never see each other's topics.
workers=$(nproc 2>/dev/null || echo 2)
if [ "$quick" = true ]; then
  echo "==> Quick tier: the unit tests only (no integration tests, no system-ROS setup test)"
  phase_start=$SECONDS
  run_pytest -n "$workers" --dist loadgroup "${unit[@]}" "${deselect[@]}" "$@"
  status=$?
  echo "==> Quick tier took $((SECONDS - phase_start)) s"
  [ "$status" = 5 ] && { echo "test.sh: pytest collected no tests" >&2; exit 1; }
  exit "$status"
fi
phase_start=$SECONDS
echo "==> Phase 1: unit tests, and $system_ros beside them"
system_ros_log=$(mktemp)
run_pytest "$system_ros" "$@" >"$system_ros_log" 2>&1 &
system_ros_pid=$!
run_pytest -n "$workers" --dist loadgroup "${unit[@]}" "${deselect[@]}" "$@"
unit_status=$?
wait "$system_ros_pid"
system_ros_status=$?
cat "$system_ros_log"
rm -f "$system_ros_log"
echo "==> Phase 1 took $((SECONDS - phase_start)) s"
phase_start=$SECONDS
# The integration tests, a whole file per worker (its module's nodes stay its own), the
# longest files first so that the two workers end together (measured: these five take
# half the phase).
integration_workers=${DAM_TEST_WORKERS:-2}
echo "==> Phase 2: integration tests on $integration_workers workers"
integration=()
for t in tests/integration/test_recorder.py tests/integration/test_shutdown_signals.py \
  tests/integration/test_bringup_scripts.py tests/integration/test_malformed_requests.py \
  tests/integration/test_recording_complete.py tests/integration/test_*.py; do
  case " ${unit[*]} $system_ros ${integration[*]} " in
    *" $t "*) ;;
    *) integration+=("$t") ;;
  esac
done
parallel=()
if [ "$integration_workers" -gt 1 ]; then
  parallel=(-n "$integration_workers" --dist loadfile)
fi
# Beside a second worker a test that fails is run once more (R, and a RERUN line naming it
# in the summary); one that fails twice fails the run.
run_pytest ${parallel[@]+"${parallel[@]}"} --durations=12 -m "not exclusive" --reruns 1 \
  "${integration[@]}" "${realtime_unit[@]}" "$@"
integration_status=$?
# Tests that load the machine on purpose (six CPU burners, storms of driver starts with a 2 s
# exit bound) run alone afterwards: beside another test's stack they would be overloaded, or
# overload it, which is not what either test is about.
echo "==> Phase 2, the tests that load the machine (marker exclusive), alone"
run_pytest -m exclusive "${integration[@]}" "$@"
exclusive_status=$?
echo "==> Phase 2 took $((SECONDS - phase_start)) s"
set -e
status=0
collected=0
for s in "$unit_status" "$system_ros_status" "$integration_status" "$exclusive_status"; do
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
