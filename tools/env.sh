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
unset _chefbot_root
