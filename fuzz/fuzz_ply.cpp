// The simulator's PLY mesh reader (ascii and binary_little_endian) on
// arbitrary bytes: a mesh whose faces index its vertices, or
// std::runtime_error naming the file.
#include <cstdint>
#include <stdexcept>
#include <string>

#include "fuzz_support.h"
#include "sl/drivers/sim.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = sl::fuzz::writeScratch("mesh.ply", data, size);
  try {
    const sl::drivers::SimMesh mesh = sl::drivers::loadPlyMesh(path, 1.0);
    for (const auto& t : mesh.triangles)
      for (const auto v : t)
        if (v < 0 || static_cast<std::size_t>(v) >= mesh.vertices.size()) __builtin_trap();
  } catch (const std::runtime_error&) {
  }
  return 0;
}
