# The runtime packages of the generators above.
set(_sl_generators rosidl_runtime_c rosidl_runtime_cpp rosidl_typesupport_interface
    rosidl_typesupport_introspection_c rosidl_typesupport_introspection_cpp)
foreach(_sl_generator ${_sl_generators})
  find_package(${_sl_generator} REQUIRED)
endforeach()
