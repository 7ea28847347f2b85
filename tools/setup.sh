#!/usr/bin/env bash
# One-command setup of locem_bridge, idempotent and quick once done:
#   1. ROS 1 from the distribution: Debian's own ROS packages (bookworm), or ros-noetic-* on Ubuntu 20.04;
#   2. a virtual environment from /usr/bin/python3 with --system-site-packages, holding requirements*.txt;
#   3. a catkin workspace (outside the repository, never in git) whose src/ links to this checkout, built with
#      catkin_make.
# Each step records what it was built from and is skipped when nothing changed. Prints the environment file to
# source at the end (tools/run.sh CMD sets up, sources it and runs CMD).
#
# Environment: LOCEM_HOME (default ~/.cache/locem_bridge) holds the venv and the workspace.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
LOCEM_HOME="${LOCEM_HOME:-${XDG_CACHE_HOME:-$HOME/.cache}/locem_bridge}"
say() { printf '[setup] %s\n' "$*" >&2; }
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

mkdir -p "$LOCEM_HOME"
# One setup at a time per LOCEM_HOME: parallel runs (several shells, CI next to a developer) wait here.
exec 9>"$LOCEM_HOME/.setup.lock"
flock 9
. /etc/os-release
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

# ---------------------------------------------------------------- 1. distribution packages
if [ "${ID:-}" = ubuntu ] && [ ! -f /opt/ros/noetic/setup.bash ]; then
  if [ "${VERSION_CODENAME:-}" != focal ]; then
    say "ROS 1 Noetic needs Ubuntu 20.04 (focal); this is Ubuntu ${VERSION_ID:-?}. Use Debian bookworm's ROS packages or focal."
    exit 1
  fi
  # Ubuntu 20.04 without Noetic yet: add the ROS package repository (packages.ros.org), then install below.
  say "adding the ROS Noetic apt repository (packages.ros.org)"
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends curl gnupg ca-certificates >/dev/null
  curl -fsSL https://raw.githubusercontent.com/ros/rosdistro/master/ros.key \
    | $SUDO gpg --batch --yes --dearmor -o /usr/share/keyrings/ros-archive-keyring.gpg
  echo "deb [signed-by=/usr/share/keyrings/ros-archive-keyring.gpg] http://packages.ros.org/ros/ubuntu focal main" \
    | $SUDO tee /etc/apt/sources.list.d/ros1-latest.list >/dev/null
fi
if [ "${ID:-}" = ubuntu ]; then
  ROS_SETUP=/opt/ros/noetic/setup.bash
  APT_PACKAGES="python3-venv python3-pip cmake g++ ros-noetic-catkin ros-noetic-rospy ros-noetic-rostest
    ros-noetic-roslaunch ros-noetic-rosservice ros-noetic-rostopic ros-noetic-rosnode ros-noetic-rosbash
    ros-noetic-actionlib ros-noetic-message-generation ros-noetic-message-runtime ros-noetic-std-msgs
    ros-noetic-actionlib-msgs ros-noetic-geometry-msgs ros-noetic-diagnostic-msgs ros-noetic-nav-msgs
    ros-noetic-tf2-ros ros-noetic-rosout"
else
  ROS_SETUP=""
  APT_PACKAGES="python3-venv python3-pip cmake g++ catkin python3-catkin-pkg ros-message-generation
    ros-message-runtime python3-genpy python3-rospy python3-rostest python3-roslaunch python3-rosservice
    python3-rostopic python3-rosnode python3-rosmaster python3-rosparam python3-rosmsg python3-rosunit rosbash
    rosout python3-actionlib python3-actionlib-msgs ros-actionlib-msgs libactionlib-msgs-dev ros-std-msgs
    python3-std-msgs libstd-msgs-dev python3-geometry-msgs libgeometry-msgs-dev python3-nav-msgs
    libnav-msgs-dev python3-diagnostic-msgs libdiagnostic-msgs-dev python3-sensor-msgs libsensor-msgs-dev
    python3-tf2-msgs libtf2-msgs-dev python3-tf2-ros
    chromium chromium-driver"
fi
# (chromium + chromium-driver: the operator HMI's real-browser test; on Ubuntu 20.04 Chromium is a snap, so
#  that test is skipped there unless /usr/bin/chromium exists.)
missing=""
for p in $APT_PACKAGES; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "${missing// /}" ]; then
  say "installing distribution packages: $missing"
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  # shellcheck disable=SC2086
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing >/dev/null
else
  say "distribution packages present"
fi

# ---------------------------------------------------------------- 2. virtual environment
VENV="$LOCEM_HOME/venv"
REQ_HASH=$(hash_of "$REPO"/requirements*.txt)
if [ ! -x "$VENV/bin/python" ]; then
  say "creating virtual environment $VENV"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
if [ "$(cat "$VENV/.locem-requirements" 2>/dev/null)" != "$REQ_HASH" ]; then
  say "installing Python requirements into $VENV"
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip >/dev/null 2>&1
  for req in "$REPO"/requirements*.txt; do
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$req" > "$LOCEM_HOME/pip.log" 2>&1 \
      || { grep -v '^WARNING: Location' "$LOCEM_HOME/pip.log" | tail -30 >&2; exit 1; }
  done
  echo "$REQ_HASH" > "$VENV/.locem-requirements"
else
  say "Python requirements present"
fi

# ---------------------------------------------------------------- 3. catkin workspace
WS="$LOCEM_HOME/ws-$(printf '%s' "$REPO" | sha256sum | cut -c1-10)"
mkdir -p "$WS/src"
if [ "$(readlink "$WS/src/locem_bridge" 2>/dev/null)" != "$REPO" ]; then
  rm -f "$WS/src/locem_bridge"
  ln -s "$REPO" "$WS/src/locem_bridge"
fi
# The venv's interpreter (made from /usr/bin/python3) builds the workspace, so the devel-space script wrappers
# that rosrun/roslaunch execute start in the venv and see its packages.
BUILD_HASH=$( (cd "$REPO" && echo "$VENV"; ls msg srv action scripts 2>/dev/null; cat CMakeLists.txt package.xml \
  setup.py msg/* srv/* action/* 2>/dev/null) | sha256sum | cut -c1-16)
if [ ! -f "$WS/devel/setup.bash" ] || [ "$(cat "$WS/.locem-build" 2>/dev/null)" != "$BUILD_HASH" ]; then
  say "building the catkin workspace $WS"
  (
    set +u
    [ -n "$ROS_SETUP" ] && . "$ROS_SETUP"
    cd "$WS"
    rm -rf "$WS/build" "$WS/devel"   # a clean configure: the interpreter or the message set may have changed
    catkin_make -DPYTHON_EXECUTABLE="$VENV/bin/python" -DCATKIN_ENABLE_TESTING=OFF > "$WS/catkin_make.log" 2>&1 \
      || { tail -40 "$WS/catkin_make.log" >&2; exit 1; }
  )
  echo "$BUILD_HASH" > "$WS/.locem-build"
else
  say "catkin workspace up to date"
fi

cat > "$LOCEM_HOME/env-$(basename "$WS").sh" <<EOF
# Generated by tools/setup.sh: source it to use locem_bridge from $REPO.
${ROS_SETUP:+. "$ROS_SETUP"}
. "$WS/devel/setup.bash"
. "$VENV/bin/activate"
export LOCEM_REPO="$REPO"
EOF
echo "$LOCEM_HOME/env-$(basename "$WS").sh"
