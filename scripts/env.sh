# Source me (bash): puts the venv, the colcon install space and the ROS 2 environment in place.
# Discovery stays on loopback; pick your own ROS_DOMAIN_ID per run to keep runs apart.
_zeus_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# shellcheck source=/dev/null
source "$_zeus_root/.venv/bin/activate"
export AMENT_PREFIX_PATH="$_zeus_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# colcon's setup scripts read unset variables: tolerate that even in `set -u` shells.
case $- in *u*) _zeus_nounset=1; set +u ;; *) _zeus_nounset= ;; esac
# shellcheck source=/dev/null
source "$_zeus_root/install/setup.bash"
[ -n "$_zeus_nounset" ] && set -u
unset _zeus_nounset
export PATH="$_zeus_root/install/zeus_ros/lib/zeus_ros:$PATH"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# RTPS on loopback only (shared memory + UDP on 127.0.0.1); an own profile, or an empty value
# for Fast DDS's defaults, is kept (several machines: docs/security.md).
export FASTRTPS_DEFAULT_PROFILES_FILE=${FASTRTPS_DEFAULT_PROFILES_FILE-$_zeus_root/params/dds/fastdds_loopback.xml}
export MUJOCO_GL=${MUJOCO_GL:-egl}
export PYOPENGL_PLATFORM=${PYOPENGL_PLATFORM:-$MUJOCO_GL}
unset _zeus_root
