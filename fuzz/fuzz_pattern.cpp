// The pattern file reader (patterns: entries and config/patterns/*.yaml) on
// arbitrary YAML text: ConfigError or a valid PatternSpec, nothing else.
#include <cstdint>
#include <string>

#include "sl/daemon/config.h"
#include "sl/files/pattern_config.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    sl::files::parsePatternText(text, "fuzz.yaml");
  } catch (const sl::files::ConfigError&) {
  }
  return 0;
}
