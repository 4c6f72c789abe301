# Daemon tests: included from tests/CMakeLists.txt.

# sl::dds wrapper and the generated types, over the loopback configuration.
sl_add_test(test_dds daemon/test_dds.cpp)
target_link_libraries(test_dds PRIVATE sl_dds sl_idl)
