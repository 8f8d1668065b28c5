# Source this file (bash) to use the workspace by hand:
#     source tools/env.sh
# It puts the venv first on PATH (Debian's rospy + pinned PyPI packages, and
# the ROS 1 'xacro' command) and sources the catkin devel space.
_chefbot_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -f "$_chefbot_root/devel/setup.bash" ]; then
    echo "chefbot: workspace not built yet: run 'make setup' in $_chefbot_root" >&2
    return 1 2>/dev/null || exit 1
fi
export PATH="$_chefbot_root/.venv/bin:/usr/bin:$PATH"
export VIRTUAL_ENV="$_chefbot_root/.venv"
# shellcheck disable=SC1091
source "$_chefbot_root/devel/setup.bash"
export PATH="$_chefbot_root/.venv/bin:$PATH"
export ROS_PYTHON_VERSION=3
# Loopback only unless asked: with ROS_HOSTNAME/ROS_IP on a loopback name every
# rospy node and the master bind their XML-RPC and TCPROS servers to 127.0.0.1
# instead of 0.0.0.0 (ROS 1 has no authentication: anyone who reaches a port can
# publish cmd_vel or shut a node down). To reach the robot from another machine
# set CHEFBOT_ROS_IP to its LAN address before sourcing this file (README.md,
# "Security and multi-machine use").
export ROS_IP="${CHEFBOT_ROS_IP:-127.0.0.1}"
export ROS_HOSTNAME="${CHEFBOT_ROS_IP:-localhost}"
# roscpp's XML-RPC server ignores both and binds 0.0.0.0: a small LD_PRELOAD shim
# (tools/loopback_bind.c, built by setup) turns wildcard binds into loopback ones.
_chefbot_lb="$_chefbot_root/build/lib/libchefbot_loopback_bind.so"
if [ -z "${CHEFBOT_ROS_IP:-}" ] && [ -f "$_chefbot_lb" ]; then
    case ":${LD_PRELOAD:-}:" in
        *":$_chefbot_lb:"*) ;;
        *) export LD_PRELOAD="$_chefbot_lb${LD_PRELOAD:+:$LD_PRELOAD}" ;;
    esac
elif [ -n "${LD_PRELOAD:-}" ]; then  # opened up after an earlier loopback-only source
    LD_PRELOAD=$(printf '%s' ":$LD_PRELOAD:" | sed "s#:$_chefbot_lb:#:#g; s#^:##; s#:\$##")
    if [ -n "$LD_PRELOAD" ]; then export LD_PRELOAD; else unset LD_PRELOAD; fi
fi
unset _chefbot_lb
unset _chefbot_root
