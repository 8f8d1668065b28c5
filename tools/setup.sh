#!/usr/bin/env bash
# Idempotent setup of the ChefBot workspace on Debian 12:
#   1. Debian packages (ROS 1 from Debian, toolchains) that are missing,
#   2. a venv in .venv built from /usr/bin/python3 --system-site-packages
#      (so Debian's rospy and PyPI's packages meet), with pinned requirements,
#   3. catkin_make of the workspace (the repository top level is the src space).
# A second run with nothing to do takes a few seconds.
# CHEFBOT_RVIZ=1 also installs the optional tools/apt-packages-rviz.txt (RViz, Xvfb).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
STAMPS="$ROOT/build/.stamps"
say() { printf '[setup] %s\n' "$*"; }

# ---------------------------------------------------------------- 1. apt
# CHEFBOT_RVIZ=1 adds the optional RViz list (rviz, its Python bindings, Xvfb).
APT_LISTS=(tools/apt-packages.txt)
if [ "${CHEFBOT_RVIZ:-0}" = "1" ]; then
    APT_LISTS+=(tools/apt-packages-rviz.txt)
    say "CHEFBOT_RVIZ=1: RViz opt-in, tools/apt-packages-rviz.txt included"
fi
mapfile -t PKGS < <(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "${APT_LISTS[@]}" | tr -d ' \t')
missing=()
for p in "${PKGS[@]}"; do
    st=$(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true)
    [ "$st" = "installed" ] || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    say "installing ${#missing[@]} Debian packages: ${missing[*]}"
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then
        command -v sudo >/dev/null || { echo "[setup] ERROR: need root (or sudo) to apt-get install: ${missing[*]}" >&2; exit 1; }
        SUDO="sudo"
    fi
    export DEBIAN_FRONTEND=noninteractive
    mkdir -p build
    say "  (apt output: build/apt-install.log; about a minute on a fresh machine)"
    if ! { $SUDO apt-get update -q && $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"; } \
            > build/apt-install.log 2>&1; then
        tail -n 30 build/apt-install.log >&2
        echo "[setup] ERROR: apt-get failed (full log: build/apt-install.log)" >&2
        exit 1
    fi
else
    say "Debian packages: all ${#PKGS[@]} present"
fi

# ---------------------------------------------------------------- 2. venv
mkdir -p "$STAMPS"
if [ ! -x "$VENV/bin/python" ]; then
    say "creating venv $VENV from /usr/bin/python3 (--system-site-packages)"
    /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
req_hash=$(sha256sum requirements.txt | cut -c1-16)
if [ "$(cat "$STAMPS/requirements" 2>/dev/null || true)" != "$req_hash" ]; then
    say "installing pinned PyPI requirements"
    # (grep drops a harmless warning some machines' pip config prints per package)
    # --require-hashes: every file must match a sha256 in requirements.txt (tools/pin_hashes.py)
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check --require-hashes -r requirements.txt 2>&1 \
        | { grep -v "^WARNING: Location 'file:" || true; }
    [ "${PIPESTATUS[0]}" -eq 0 ] || { echo "[setup] ERROR: pip install failed" >&2; exit 1; }
    echo "$req_hash" > "$STAMPS/requirements"
else
    say "venv requirements up to date"
fi

# ---------------------------------------------------------------- 3. catkin
# Put the venv first so catkin, roslaunch and '#!/usr/bin/env python3' nodes
# all run the venv's interpreter, not pyenv's (which cannot import rospy).
export PATH="$VENV/bin:/usr/bin:$PATH"
# Skip the build when no package.xml/CMakeLists/setup.py/msg changed since last time.
src_hash=$(find . -path ./.venv -prune -o -path ./build -prune -o -path ./devel -prune -o -path ./.git -prune -o -path ./CMakeLists.txt -prune -o \
            \( -name package.xml -o -name CMakeLists.txt -o -name setup.py -o -name '*.msg' -o -name '*.srv' -o -name '*.action' \) \
            -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -c1-16)
if [ "$(cat "$STAMPS/catkin" 2>/dev/null || true)" != "$src_hash" ] || [ ! -f devel/setup.bash ]; then
    say "building the catkin workspace"
    # catkin_pkg skips hidden directories; build/ and devel/ need CATKIN_IGNORE.
    mkdir -p build devel && touch build/CATKIN_IGNORE devel/CATKIN_IGNORE
    catkin_make --source "$ROOT" --directory "$ROOT" \
        -DPYTHON_EXECUTABLE="$VENV/bin/python" -DCATKIN_ENABLE_TESTING=ON \
        -DCMAKE_BUILD_TYPE=Release > build/catkin_make.log 2>&1 || {
            tail -n 40 build/catkin_make.log >&2
            echo "[setup] ERROR: catkin_make failed, full log: build/catkin_make.log" >&2
            exit 1
        }
    echo "$src_hash" > "$STAMPS/catkin"
else
    say "catkin workspace up to date"
fi
# ---------------------------------------------------------------- 4. firmware host library
# The simulator and the driver tests load it with ctypes (incremental, quiet).
if [ -f firmware/Makefile ]; then
    make -s -C firmware lib || { echo "[setup] ERROR: building the firmware host library failed" >&2; exit 1; }
fi
# ---------------------------------------------------------------- 5. loopback bind shim
# tools/env.sh preloads it so C++ nodes' XML-RPC servers bind 127.0.0.1 (see the source).
LB_SO="$ROOT/build/lib/libchefbot_loopback_bind.so"
if [ ! -f "$LB_SO" ] || [ tools/loopback_bind.c -nt "$LB_SO" ]; then
    mkdir -p "$ROOT/build/lib"
    gcc -O2 -Wall -Wextra -Werror -shared -fPIC -o "$LB_SO" tools/loopback_bind.c -ldl \
        || { echo "[setup] ERROR: building tools/loopback_bind.c failed" >&2; exit 1; }
fi
say "ready — 'source tools/env.sh' for manual roslaunch/rosrun"
