#!/usr/bin/env bash
# ros2/sl_msgs builds as a ROS 2 interface package with Debian's ament_cmake
# and rosidl (C and C++ generators, introspection typesupports), the way colcon
# builds a workspace: each package configured, built and installed into one
# prefix in dependency order. ROS 2's builtin_interfaces, std_msgs,
# sensor_msgs and rosidl_default_generators/_runtime are not packaged by
# Debian: standins/ holds build-time stand-ins (see standins/README.md).
# Then a C++ program compiled against the installed sl_msgs reads the
# generated introspection data: every .msg/.srv field is there, in order,
# with the constants' values.
# usage: build_sl_msgs.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
src=$1
bin=$2
work=$(mktemp -d "$bin/ros2_sl_msgs.XXXXXX")
trap '[ -n "${KEEP:-}" ] || rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# ament and rosidl run Debian's Python (python3-rosidl), not another python3
# first in PATH.
export PATH=/usr/bin:$PATH
prefix=$work/install
export CMAKE_PREFIX_PATH=$prefix
export AMENT_PREFIX_PATH=$prefix:/usr
for pkg in rosidl_default_generators rosidl_default_runtime builtin_interfaces std_msgs sensor_msgs sl_msgs; do
  if [ $pkg = sl_msgs ]; then dir=$src/ros2/sl_msgs; else dir=$src/tests/ros2/standins/$pkg; fi
  log=$work/$pkg.log
  if ! { cmake -S "$dir" -B "$work/build/$pkg" -DCMAKE_INSTALL_PREFIX="$prefix" \
           -DPython3_EXECUTABLE=/usr/bin/python3 -DBUILD_TESTING=OFF &&
         cmake --build "$work/build/$pkg" -j2 &&
         cmake --install "$work/build/$pkg"; } > "$log" 2>&1; then
    tail -n 40 "$log" >&2
    fail "package $pkg did not build (log above)"
  fi
  echo "built $pkg"
done

for f in "$src"/ros2/sl_msgs/msg/*.msg "$src"/ros2/sl_msgs/srv/*.srv; do
  kind=$(basename "$(dirname "$f")")
  name=$(basename "${f%.*}")
  snake=$(echo "$name" | sed -E 's/([a-z0-9])([A-Z])/\1_\2/g' | tr 'A-Z' 'a-z')
  [ -f "$prefix/include/sl_msgs/sl_msgs/$kind/$snake.hpp" ] ||
  [ -f "$prefix/include/sl_msgs/$kind/$snake.hpp" ] ||
    fail "no C++ header generated for $kind/$name"
done
echo "every msg/srv has its generated C++ header"

includes=()
for pkg in builtin_interfaces std_msgs sensor_msgs sl_msgs; do includes+=(-I "$prefix/include/$pkg"); done
for dir in /usr/include/rosidl_runtime_cpp /usr/include/rosidl_runtime_c /usr/include/rosidl_typesupport_interface; do
  [ -d "$dir" ] && includes+=(-I "$dir")
done
c++ -std=c++17 -Wall -Wextra -Werror "${includes[@]}" "$src/tests/ros2/sl_msgs_user.cpp" -o "$work/sl_msgs_user" ||
  fail "a program using the generated C++ types of sl_msgs does not compile"
out=$("$work/sl_msgs_user") || fail "sl_msgs_user exited non-zero"
[ "$out" = "3+3 1 1" ] || fail "sl_msgs_user printed '$out', expected '3+3 1 1'"
echo "a downstream C++ program compiles and runs against the installed sl_msgs"
