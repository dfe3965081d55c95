#!/usr/bin/env bash
# Generate and install ROS 2 interface packages into a pip-installed ROS 2 Jazzy prefix (a venv).
#   interfaces/build_interfaces.sh VENV [PKG...]
# PKG names a package folder under interfaces/ (default: every one). No wheel exists of these
# packages; the rosidl generator wheels do. Each is an ordinary ament_cmake /
# rosidl_generate_interfaces build with the venv as the install prefix, so the package lands next
# to the message wheels (Python package in site-packages, libraries in VENV/lib), built in the
# order given. The libraries load whatever LD_LIBRARY_PATH the process inherited: each carries
# an $ORIGIN-relative RPATH to VENV/lib (CMAKE_INSTALL_RPATH), where the others and the message
# libraries they link are, and the typesupport dispatch libraries link their implementations
# (interfaces/cmake/wheel_prefix.cmake, included into each package's project).
# A package is left alone when it comes from elsewhere (a ROS installation, a sourced
# workspace), or when it was generated here that way from the same definitions.
set -euo pipefail
VENV=$(cd "$1" && pwd -P)
shift
PY="$VENV/bin/python"
HERE=$(cd "$(dirname "$0")" && pwd)
if [ $# -eq 0 ]; then
    set -- $(cd "$HERE" && for f in */package.xml; do dirname "$f"; done)
fi
SITE=$("$PY" -c 'import sysconfig; print(sysconfig.get_path("platlib"))')

definitions() {     # the interface files of a package folder, one path a line
    (cd "$1" 2>/dev/null && ls -1 msg/*.msg srv/*.srv action/*.action 2>/dev/null || true)
}

current() {         # PKG: 0 when there is nothing to do
    local pkg=$1 found dyn f
    found=$("$PY" -c "import os, $pkg.msg; print(os.path.realpath($pkg.__file__))" \
        2>/dev/null || true)
    case "$found" in
        '') return 1 ;;
        "$VENV"/*) ;;
        *) return 0 ;;
    esac
    dyn=$(readelf -d "$VENV/lib/lib${pkg}__rosidl_typesupport_c.so" 2>/dev/null || true)
    grep -q 'PATH.*\$ORIGIN' <<< "$dyn" || return 1
    grep -q "lib${pkg}__rosidl_typesupport_introspection_c" <<< "$dyn" || return 1
    [ "$(definitions "$HERE/$pkg")" = "$(definitions "$VENV/share/$pkg")" ] || return 1
    for f in $(definitions "$HERE/$pkg"); do
        cmp -s "$HERE/$pkg/$f" "$VENV/share/$pkg/$f" || return 1
    done
}

build() {           # PKG
    local pkg=$1 up build start=$SECONDS
    # The libraries go to VENV/lib, the Python extensions to SITE/PKG: both look in VENV/lib.
    up=$("$PY" -c 'import os, sys; print(os.path.relpath(sys.argv[1], sys.argv[2]))' \
        "$VENV/lib" "$SITE/$pkg")
    build=$(mktemp -d)
    cmake -S "$HERE/$pkg" -B "$build" -DCMAKE_INSTALL_PREFIX="$VENV" \
        -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY" \
        -DCMAKE_PROJECT_INCLUDE="$HERE/cmake/wheel_prefix.cmake" \
        -DCMAKE_INSTALL_RPATH="\$ORIGIN;\$ORIGIN/$up" \
        > "$build/configure.log" 2>&1 || { tail -40 "$build/configure.log"; rm -rf "$build"; exit 1; }
    cmake --build "$build" -j "$(nproc)" > "$build/build.log" 2>&1 \
        || { tail -40 "$build/build.log"; rm -rf "$build"; exit 1; }
    # an earlier generation of the package goes first: no definition it no longer has stays
    rm -rf "${VENV:?}/share/$pkg" "${VENV:?}/include/$pkg" "${SITE:?}/$pkg"
    cmake --install "$build" > /dev/null
    rm -rf "$build"
    "$PY" -c "import $pkg.msg"
    echo "$pkg generated into $VENV ($((SECONDS - start)) s)"
}

command -v cmake >/dev/null || "$VENV/bin/pip" install -q cmake
export PATH="$VENV/bin:$PATH" AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
for pkg in "$@"; do
    [ -f "$HERE/$pkg/package.xml" ] || { echo "interfaces/$pkg: no package.xml there" >&2; exit 2; }
    current "$pkg" || build "$pkg"
done
