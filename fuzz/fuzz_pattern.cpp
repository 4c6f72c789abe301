// The pattern file reader (patterns: entries and config/patterns/*.yaml) on
// arbitrary YAML text: ConfigError or a valid PatternSpec, nothing else.
#include <cstdint>
#include <string>

#include "sl/daemon/config.h"
#include "sl/daemon/pattern_config.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    sl::daemon::parsePatternText(text, "fuzz.yaml");
  } catch (const sl::daemon::ConfigError&) {
  }
  return 0;
}
