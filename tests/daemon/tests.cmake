# Daemon tests: included from tests/CMakeLists.txt.

# sl::dds wrapper and the generated types, over the loopback configuration.
sl_add_test(test_dds daemon/test_dds.cpp)
target_link_libraries(test_dds PRIVATE sl_dds sl_idl)

# End to end: sl_sensord in a child process on the simulated sensor.
sl_add_test(test_e2e daemon/test_e2e.cpp daemon/test_bridge.cpp daemon/test_cloud_writer.cpp)
target_link_libraries(test_e2e PRIVATE sl_daemon sl_drivers sl_dds sl_idl yaml-cpp)
target_include_directories(test_e2e PRIVATE ${PROJECT_SOURCE_DIR}/daemon/src)  # cloud_writer.h
add_dependencies(test_e2e sl_sensord malformed_writer points_subscriber sl_view)  # sl_view record

# A client whose requests the daemon cannot deserialize (test_e2e): a
# look-alike CommandRequest without type information (a string sent without
# its terminating NUL).
set(_lookalike_dir ${CMAKE_CURRENT_BINARY_DIR}/lookalike)
find_program(SL_IDLC idlc REQUIRED)  # Debian's cyclonedds-tools (as idlc_generate uses)
add_custom_command(
  OUTPUT ${_lookalike_dir}/CommandRequest.c ${_lookalike_dir}/CommandRequest.h
  COMMAND ${CMAKE_COMMAND} -E make_directory ${_lookalike_dir}
  COMMAND ${SL_IDLC} -t -o ${_lookalike_dir}
          ${CMAKE_CURRENT_SOURCE_DIR}/daemon/lookalike/CommandRequest.idl
  DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/daemon/lookalike/CommandRequest.idl
  VERBATIM)
add_executable(malformed_writer daemon/lookalike/malformed_writer.c ${_lookalike_dir}/CommandRequest.c)
target_include_directories(malformed_writer PRIVATE ${_lookalike_dir})
target_link_libraries(malformed_writer PRIVATE CycloneDDS::ddsc)

# A subscriber of the points topic in its own process (test_e2e): one that
# reads, one that stops reading.
add_executable(points_subscriber daemon/points_subscriber.c)
target_link_libraries(points_subscriber PRIVATE sl_idl CycloneDDS::ddsc)

# ScanEngine without DDS: health (feeds the systemd watchdog), requests,
# software trigger; its stages without threads (start validation, set
# processing, the adaptive-scanning policy); BoundedQueue's overflow policies.
sl_add_test(test_engine daemon/test_engine.cpp daemon/test_engine_stages.cpp
  daemon/test_bounded_queue.cpp daemon/test_adaptive.cpp)
target_link_libraries(test_engine PRIVATE sl_daemon sl_drivers)
# The engine's stages are private to the daemon (daemon/src/engine/).
target_include_directories(test_engine PRIVATE ${PROJECT_SOURCE_DIR}/daemon/src)

# The DDS edge without DDS: message builders, request dispatch, frame ids.
sl_add_test(test_messages daemon/test_messages.cpp daemon/test_ros_graph.cpp)
target_link_libraries(test_messages PRIVATE sl_daemon sl_idl)
target_include_directories(test_messages PRIVATE ${PROJECT_SOURCE_DIR}/daemon/src)

# Issue 36 probes: one daemon per namespace (instance lock), reloads that
# block, config checks before any device, calibration files bounded.
sl_add_test(test_hardening daemon/test_hardening.cpp)
target_link_libraries(test_hardening PRIVATE sl_daemon yaml-cpp)
target_include_directories(test_hardening PRIVATE ${PROJECT_SOURCE_DIR}/daemon/src)
add_dependencies(test_hardening sl_sensord)

# Config loading and its error messages.
sl_add_test(test_config daemon/test_config.cpp sim/test_sim_config.cpp)
target_link_libraries(test_config PRIVATE sl_daemon opencv_imgcodecs)

# End to end through slctl and the plain C subscriber.
add_test(NAME e2e_cli COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/e2e_cli.sh
  ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
set_tests_properties(e2e_cli PROPERTIES TIMEOUT 300)

# Recording faults (issue 36): a full disk (a small tmpfs in a private mount
# namespace; skipped, exit 77, where none can be made) and kill -9 during a
# recording.
add_test(NAME recording_faults COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/recording_faults.sh
  ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
set_tests_properties(recording_faults PROPERTIES TIMEOUT 120 SKIP_RETURN_CODE 77)

# The README's first-scan block, as pasted, against the simulated daemon.
add_test(NAME readme_first_scan COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/readme_first_scan.sh
  ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
set_tests_properties(readme_first_scan PROPERTIES TIMEOUT 300)

# Every tool: --help exits 0, an unknown or misplaced option exits 2 with the usage.
add_test(NAME tools_usage COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/tools_usage.sh ${PROJECT_BINARY_DIR})

# The systemd unit passes systemd-analyze verify.
add_test(NAME systemd_unit COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/verify_unit.sh
  ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})

# A participant that publishes forged clouds on a points topic (dds_security).
add_executable(forged_points daemon/forged_points.c)
target_link_libraries(forged_points PRIVATE sl_idl CycloneDDS::ddsc)

# DDS Security: identities, governance and permissions (scripts/dds-security.sh).
add_test(NAME dds_security COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/daemon/security.sh
  ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
set_tests_properties(dds_security PROPERTIES TIMEOUT 180)

# rmw_fastrtps's plain service samples <-> rmw_cyclonedds's framing (sl/dds/ros2_service.h).
sl_add_test(test_service_framing daemon/test_service_framing.cpp)
target_link_libraries(test_service_framing PRIVATE sl_dds sl_idl)
