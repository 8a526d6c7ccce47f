#!/usr/bin/env bash
# Run the whole test suite: set up and build (scripts/setup.sh), then pytest over tests/.
#
#   bash scripts/test.sh                 # everything
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
test_dirs=()
if [ "$paths_given" = false ]; then
  test_dirs=(tests)
  for pkg_tests in src/*/test; do
    if [ -d "$pkg_tests" ]; then test_dirs+=("$pkg_tests"); fi
  done
fi
set +e
python -m pytest -p no:cacheprovider -ra "${test_dirs[@]}" "$@"
status=$?
set -e
if [ "$status" = 5 ]; then
  echo "test.sh: pytest collected no tests" >&2
  exit 1
fi
exit "$status"
