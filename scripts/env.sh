# shellcheck shell=bash
# The one definition of the bfr environment (build and run time). Source it from bash:
#
#     . scripts/env.sh
#
# scripts/setup, scripts/test, scripts/bfr and scripts/demo all source this file (and .ci/run
# through scripts/test), so every entry point sees the same environment. It only sets
# variables; it installs and builds nothing (that is scripts/setup's job). Sourcing it twice
# is harmless. Do not mix it with a sourced system ROS (/opt/ros/jazzy/setup.bash).

BFR_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export BFR_ROOT
export BFR_VENV="${BFR_ROOT}/.venv"
BFR_PYTHON_VERSION="3.11"
_bfr_site="${BFR_VENV}/lib/python${BFR_PYTHON_VERSION}/site-packages"

# _bfr_prepend VAR DIR: put DIR first in the colon-separated list VAR, once.
_bfr_prepend() {
  local var="$1" dir="$2" cur
  cur="${!var-}"
  cur=":${cur}:"
  cur="${cur//:${dir}:/:}"
  cur="${cur#:}"
  cur="${cur%:}"
  if [ -n "$cur" ]; then
    export "$var=${dir}:${cur}"
  else
    export "$var=${dir}"
  fi
}

# The Python virtual environment holding ROS 2 Jazzy (PyPI wheels) and every dependency.
export VIRTUAL_ENV="$BFR_VENV"
_bfr_prepend PATH "${BFR_VENV}/bin"
unset PYTHONHOME

# Shared libraries of the ROS wheels: the venv's lib/ and the wheels' bundled ros_*.libs.
# The wheels ship a .pth hook (ros_wheels_bootstrapper) that sets this and re-executes every
# Python process; setting it here once and marking it done avoids that second start.
for _bfr_dir in "${_bfr_site}"/ros_*.libs; do
  [ -d "$_bfr_dir" ] && _bfr_prepend LD_LIBRARY_PATH "$_bfr_dir"
done
_bfr_prepend LD_LIBRARY_PATH "${BFR_VENV}/lib"
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1

# ROS 2: distribution, middleware (Fast DDS), where packages and CMake configs live.
export ROS_DISTRO=jazzy
export ROS_VERSION=2
export ROS_PYTHON_VERSION=3
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
# Discovery stays on this machine (ROS 2 Jazzy: LOCALHOST, SUBNET, OFF, SYSTEM_DEFAULT): a
# shared network never sees these nodes and they never see another lab's. To reach a real
# rig's drivers on another computer, set it before sourcing this file:
#     ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET . scripts/env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_LOG_DIR="${ROS_LOG_DIR:-${BFR_ROOT}/log/ros}"
_bfr_prepend AMENT_PREFIX_PATH "$BFR_VENV"
_bfr_prepend CMAKE_PREFIX_PATH "$BFR_VENV"

# The workspace's own packages, once built (adds install/<pkg> to AMENT_PREFIX_PATH,
# CMAKE_PREFIX_PATH, PYTHONPATH and LD_LIBRARY_PATH, exactly as on a real Jazzy install).
# scripts/setup sets BFR_ENV_SKIP_INSTALL=1 to build against the venv alone.
if [ -z "${BFR_ENV_SKIP_INSTALL:-}" ] && [ -f "${BFR_ROOT}/install/local_setup.bash" ] \
  && [ -x "${BFR_VENV}/bin/python3" ]; then
  case "$-" in *u*) _bfr_had_u=1; set +u ;; *) _bfr_had_u=0 ;; esac
  # shellcheck disable=SC1091
  . "${BFR_ROOT}/install/local_setup.bash"
  [ "$_bfr_had_u" = 1 ] && set -u
  unset _bfr_had_u
fi

unset _bfr_dir _bfr_site
