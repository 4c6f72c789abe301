// The one reader of files a user names (config, pattern files, calibrations,
// meshes, textures, recordings' index files and frames): regular files only,
// a size limit per kind checked before anything is read, and for YAML one
// document with bounded anchors, aliases and nesting. Every refusal is a
// ConfigError whose message starts with the file's path (sl_sensord exits 2).
//
// Thread-safe (no shared state).
#pragma once

#include <cstdint>
#include <string>

#include <yaml-cpp/yaml.h>

namespace sl::files {

enum class InputKind {
  kConfig,             // sl_sensord --config
  kPattern,            // pattern files (patterns[].file)
  kCalibration,        // calibration YAML/XML, OpenCV key mappings
  kProjectorResponse,  // decoder.projector_response
  kMesh,               // sim scene meshes (PLY)
  kTexture,            // sim albedo textures (PNG, ...)
  kRecordingIndex,     // a recording's meta.yml / index files
  kRecordingFrame,     // a recording's frames (PNG)
};

// What the kind is called in messages ("config file") and its size limit.
const char* inputKindName(InputKind kind);
std::uintmax_t inputSizeLimit(InputKind kind);

// Limits of a YAML document (billion-laughs and nesting bombs): yaml-cpp
// shares an aliased node instead of copying it, but every walk over the tree
// (key checks, comparisons, dumps) expands it.
constexpr int kMaxYamlAliases = 64;
constexpr int kMaxYamlAnchors = 256;
constexpr int kMaxYamlDepth = 64;

// Opens `path` without blocking (O_NONBLOCK: a FIFO with no writer does not
// hang), checks with fstat that it is a regular file no larger than the
// kind's limit, and reads it whole. Throws ConfigError "path: ...".
std::string readInputFile(const std::string& path, InputKind kind);

// The same checks without reading, for files another library reads by path
// (OpenCV); returns the file's size in bytes.
std::uintmax_t checkInputFile(const std::string& path, InputKind kind);

// Parses `text` as exactly one YAML document (an empty text is one null
// document) within the limits above; `origin` names the file in errors
// ("origin:line: ..."). Throws ConfigError.
YAML::Node parseInputYaml(const std::string& text, const std::string& origin);

// readInputFile + parseInputYaml.
YAML::Node loadInputYaml(const std::string& path, InputKind kind);

}  // namespace sl::files
