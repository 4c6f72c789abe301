// Shared by the libFuzzer targets: a scratch directory per process (in
// /dev/shm when there is one) for readers that take a path, and the rule
// that a reader may throw only its documented error types.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace sl::fuzz {

// Removed when the process ends normally (libFuzzer exits through exit()).
struct ScratchDir {
  std::filesystem::path path;
  ScratchDir() {
    const std::filesystem::path base =
        std::filesystem::exists("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
    path = base / ("sl-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
};

inline const std::filesystem::path& scratchDir() {
  static const ScratchDir dir;
  return dir.path;
}

inline std::string writeScratch(const std::string& name, const std::uint8_t* data, std::size_t size) {
  const auto path = scratchDir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path.string();
}

}  // namespace sl::fuzz
