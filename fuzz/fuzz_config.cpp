// The daemon's config reader on arbitrary YAML text. Files the text names
// (patterns, calibrations, meshes) resolve relative to the scratch folder.
// Any problem must be a ConfigError; anything else (a crash, another
// exception, a sanitizer report, a timeout) is a finding.
#include <cstdint>
#include <filesystem>
#include <string>

#include "fuzz_support.h"
#include "sl/daemon/config.h"

// The files the seeds name (calibration.yaml, mesh.ply, pattern.yaml) beside
// the fuzzed config.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  for (const auto& entry : std::filesystem::directory_iterator(std::string(SL_FUZZ_DIR) + "/data"))
    std::filesystem::copy_file(entry.path(), sl::fuzz::scratchDir() / entry.path().filename(),
                               std::filesystem::copy_options::overwrite_existing);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    sl::daemon::parseConfig(text, (sl::fuzz::scratchDir() / "fuzz.yaml").string());
  } catch (const sl::files::ConfigError&) {
  }
  return 0;
}
