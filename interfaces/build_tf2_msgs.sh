#!/usr/bin/env bash
# Generate and install tf2_msgs (TFMessage) into a pip-installed ROS 2 Jazzy prefix (a venv).
#   interfaces/build_tf2_msgs.sh VENV
# No tf2_msgs wheel exists; the rosidl generator wheels do. This runs the ordinary ament_cmake /
# rosidl_generate_interfaces build of interfaces/tf2_msgs with the venv as the install prefix, so
# tf2_msgs lands next to the other message wheels (Python package in site-packages, libraries in
# VENV/lib). The libraries load whatever LD_LIBRARY_PATH the process inherited: each carries
# an $ORIGIN-relative RPATH to VENV/lib (CMAKE_INSTALL_RPATH), where the others and the message
# libraries they link are, and the typesupport dispatch libraries link their implementations
# (interfaces/tf2_msgs/CMakeLists.txt). Nothing is done when tf2_msgs comes from elsewhere (a
# ROS installation) or was generated here that way.
set -euo pipefail
VENV=$(cd "$1" && pwd -P)
PY="$VENV/bin/python"
HERE=$(cd "$(dirname "$0")" && pwd)
FOUND=$("$PY" -c 'import os, tf2_msgs.msg; print(os.path.realpath(tf2_msgs.__file__))' \
    2>/dev/null || true)
case "$FOUND" in
    '') ;;
    "$VENV"/*)
        DYN=$(readelf -d "$VENV/lib/libtf2_msgs__rosidl_typesupport_c.so" 2>/dev/null || true)
        if grep -q 'PATH.*\$ORIGIN' <<< "$DYN" \
                && grep -q 'libtf2_msgs__rosidl_typesupport_introspection_c' <<< "$DYN"; then
            exit 0
        fi ;;
    *) exit 0 ;;
esac
command -v cmake >/dev/null || "$VENV/bin/pip" install -q cmake
# The libraries go to VENV/lib, the Python extensions to SITE/tf2_msgs: both look in VENV/lib.
SITE=$("$PY" -c 'import sysconfig; print(sysconfig.get_path("platlib"))')
UP=$("$PY" -c 'import os, sys; print(os.path.relpath(sys.argv[1], sys.argv[2]))' \
    "$VENV/lib" "$SITE/tf2_msgs")
BUILD=$(mktemp -d)
trap 'rm -rf "$BUILD"' EXIT
export PATH="$VENV/bin:$PATH" AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
cmake -S "$HERE/tf2_msgs" -B "$BUILD" -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY" \
    -DCMAKE_INSTALL_RPATH="\$ORIGIN;\$ORIGIN/$UP" \
    > "$BUILD/configure.log" 2>&1 || { tail -40 "$BUILD/configure.log"; exit 1; }
cmake --build "$BUILD" -j "$(nproc)" > "$BUILD/build.log" 2>&1 \
    || { tail -40 "$BUILD/build.log"; exit 1; }
cmake --install "$BUILD" > /dev/null
"$PY" -c 'from tf2_msgs.msg import TFMessage'
echo "tf2_msgs generated into $VENV"
