// Pattern files: a PatternSpec described in YAML (schema in README.md,
// "Pattern files"; presets in config/patterns/). Parsed here and only here;
// the daemon config's `patterns:` list uses the same keys.
#pragma once

#include <string>

#include "sl/pipeline/pattern_spec.h"

namespace sl::daemon {

// Reads a pattern file. `name` defaults to the file's stem. Throws
// ConfigError naming the file, the line and the key on any problem
// (unknown key, wrong type, invalid value).
pipeline::PatternSpec loadPattern(const std::string& path);

// Same, from YAML text; `origin` names it in error messages.
pipeline::PatternSpec parsePatternText(const std::string& yaml_text, const std::string& origin,
                                       const std::string& default_name = "pattern");

}  // namespace sl::daemon
