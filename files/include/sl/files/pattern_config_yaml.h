// Pattern keys of a YAML map (private to daemon/): shared by pattern files
// and the daemon config's `patterns:` list.
#pragma once

#include <string>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/pattern_spec.h"
#include "yaml_reader.h"

namespace sl::files {

// Reads the pattern keys of `m` and calls m.done(). `name` is used when the
// map has no `name` key (empty = the key is required). With `projector`, the
// projector size defaults to it and an explicit `projector:` must match it;
// without, it defaults to 1824 x 1140. Relative `file:` paths (daemon list
// items that point at a pattern file) resolve against `base_dir`.
pipeline::PatternSpec parsePattern(const YamlMap& m, const std::string& name,
                                   const pipeline::PinholeModel* projector,
                                   const std::string& base_dir);

}  // namespace sl::files
