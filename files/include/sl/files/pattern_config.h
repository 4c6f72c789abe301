// Pattern files: a PatternSpec described in YAML (schema in README.md,
// "Pattern files"; presets in config/patterns/). Parsed here and only here;
// the daemon config's `patterns:` list uses the same keys.
#pragma once

#include <string>
#include <vector>

#include "sl/pipeline/pattern_spec.h"

namespace sl::files {

// Reads a pattern file. `name` defaults to the file's stem. Throws
// ConfigError naming the file, the line and the key on any problem
// (unknown key, wrong type, invalid value).
pipeline::PatternSpec loadPattern(const std::string& path);

// Same, from YAML text; `origin` names it in error messages.
pipeline::PatternSpec parsePatternText(const std::string& yaml_text, const std::string& origin,
                                       const std::string& default_name = "pattern");

// The pattern file text of `spec`: the keys loadPattern() reads, every one
// of the family written out (numbers with 17 significant digits), so that
// parsePatternText() of it gives `spec` back (the start phase to rounding).
// Recordings keep it per set (drivers/recording.h, pattern.yml).
std::string patternYaml(const pipeline::PatternSpec& spec);

// How two descriptions of a sequence differ, the names aside: one line per
// differing key, "key: <a> vs <b>" (values as in patternYaml(), to 9
// significant digits), the frame count first. Empty when both describe the
// same projected sequence.
std::vector<std::string> patternDifferences(const pipeline::PatternSpec& a,
                                            const pipeline::PatternSpec& b);

}  // namespace sl::files
