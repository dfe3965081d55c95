#!/usr/bin/env bash
# Generate and install tf2_msgs (TFMessage) into a pip-installed ROS 2 Jazzy prefix (a venv).
#   interfaces/build_tf2_msgs.sh VENV
# No tf2_msgs wheel exists; the rosidl generator wheels do. This runs the ordinary ament_cmake /
# rosidl_generate_interfaces build of interfaces/tf2_msgs with the venv as the install prefix, so
# tf2_msgs lands next to the other message wheels (Python package in site-packages, libraries in
# VENV/lib, found through the LD_LIBRARY_PATH the ROS wheels set up). Nothing is done when
# tf2_msgs already imports (a ROS installation, or an earlier run).
set -euo pipefail
VENV=$(cd "$1" && pwd)
PY="$VENV/bin/python"
HERE=$(cd "$(dirname "$0")" && pwd)
if "$PY" -c 'from tf2_msgs.msg import TFMessage' 2>/dev/null; then
    exit 0
fi
command -v cmake >/dev/null || "$VENV/bin/pip" install -q cmake
BUILD=$(mktemp -d)
trap 'rm -rf "$BUILD"' EXIT
export PATH="$VENV/bin:$PATH" AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
cmake -S "$HERE/tf2_msgs" -B "$BUILD" -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY" \
    > "$BUILD/configure.log" 2>&1 || { tail -40 "$BUILD/configure.log"; exit 1; }
cmake --build "$BUILD" -j "$(nproc)" > "$BUILD/build.log" 2>&1 \
    || { tail -40 "$BUILD/build.log"; exit 1; }
cmake --install "$BUILD" > /dev/null
"$PY" -c 'from tf2_msgs.msg import TFMessage'
echo "tf2_msgs generated into $VENV"
