# Sourced by scripts: reserve a ROS_DOMAIN_ID that no other run on this machine holds.
# The reservation is a lock on $TMPDIR/dam-ros-domains/<id>.lock held by this shell (fd
# DAM_DOMAIN_LOCK_FD) until it exits. Honours an already exported ROS_DOMAIN_ID if
# DAM_KEEP_DOMAIN=1.
dam_reserve_ros_domain() {
  if [ "${DAM_KEEP_DOMAIN:-0}" = 1 ] && [ -n "${ROS_DOMAIN_ID:-}" ]; then
    return 0
  fi
  local lock_dir="${TMPDIR:-/tmp}/dam-ros-domains" offset candidate fd
  mkdir -p "$lock_dir"
  for offset in $(seq 0 100); do
    candidate=$(( (offset + $$) % 101 + 1 ))  # 1..101, starting at a PID-dependent id
    exec {fd}>"$lock_dir/$candidate.lock"
    if flock -n "$fd"; then
      export ROS_DOMAIN_ID="$candidate" DAM_DOMAIN_LOCK_FD="$fd"
      return 0
    fi
    exec {fd}>&-
  done
  echo "every ROS_DOMAIN_ID 1..101 is reserved by another run on this machine" >&2
  return 1
}
