# The generators Debian packages: C and C++ with their introspection
# typesupports (a ROS 2 distribution adds Python, rosidl_typesupport_c/cpp and
# the middlewares' typesupports).
set(_sl_generators rosidl_cmake rosidl_generator_c rosidl_generator_cpp
    rosidl_typesupport_introspection_c rosidl_typesupport_introspection_cpp)
foreach(_sl_generator ${_sl_generators})
  find_package(${_sl_generator} REQUIRED)
endforeach()
