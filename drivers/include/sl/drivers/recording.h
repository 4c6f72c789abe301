// Recorded image sets on disk, written by the daemon's recorder and played
// back by the replay sensor.
//
// Format (sl-sensor-recording/1), one folder per recording:
//   <dir>/recording.yml          format, creation time, free-text note
//   <dir>/set_000001/meta.yml    sequence_id, pattern, trigger_stamp_ns and
//                                per camera: id, bit_depth, stamps_ns[]
//   <dir>/set_000001/pattern.yml the pattern file of the projected sequence
//                                (files::patternYaml(); sets written with
//                                a description only, recordings before it
//                                have none): sl_process checks it
//   <dir>/set_000001/<camera>_<i>.png   frame i of that camera, lossless PNG
//                                (8-bit, or 16-bit for deeper sensors)
// Sets are numbered in recording order from 1. The .yml files are OpenCV
// FileStorage YAML. A set is written as <dir>/set_000001.partial/ and
// renamed to set_000001 once every file of it is written and checked (close
// included); a failed write removes the partial folder. So a set folder is
// complete, and an interrupted recording (kill -9, full disk) loses at most
// the set being written, left as a .partial folder (or, from recordings
// before this scheme, a set folder without meta.yml) that readers skip and
// incompleteRecordedSets() names.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "sl/pipeline/types.h"

namespace sl::drivers {

// Creates `dir` (and recording.yml) if needed. Throws std::runtime_error
// naming the path on failure.
void createRecording(const std::string& dir, const std::string& note);

// Writes `set` as set number `index` (1-based), with `pattern_yaml` (the
// pattern file text of the set's pattern, if not empty) as its pattern.yml.
// Throws std::runtime_error naming the file on failure, or naming the set
// folder when it exists already (a recorded set is never replaced).
void writeRecordedSet(const std::string& dir, std::uint64_t index, const pipeline::ImageSet& set,
                      const std::string& pattern_yaml = "");

// The number the next set written into `dir` gets: one past the highest
// set number there, complete or not (so nothing is overwritten).
std::uint64_t nextRecordedSetIndex(const std::string& dir);

// One message per set folder of `dir` that readers skip as incomplete,
// naming the folder or its missing meta.yml; empty when none.
std::vector<std::string> incompleteRecordedSets(const std::string& dir);

// The file name of a set's pattern description in its folder.
inline constexpr const char* kRecordedPatternFile = "pattern.yml";

// The complete sets of a recording, in order (folder names only; no images
// are loaded). Throws std::runtime_error if `dir` is not a recording.
std::vector<std::string> listRecordedSets(const std::string& dir);

// Loads one set folder; with load_images false only its metadata (frames
// stay empty, stamps are filled). Throws std::runtime_error naming the file
// on a missing or unreadable frame or a malformed meta.yml.
pipeline::ImageSet readRecordedSet(const std::string& set_dir, bool load_images = true);

// A recording opened for playing back: a recording folder (above), or an
// MCAP file written by `sl_view record` with the daemon's image sets
// (rt/<ns>/image_sets, sl_msgs/msg/ImageSet) in it. Both give the same
// ImageSets for the same sets. Immutable after open(); load() is
// thread-safe.
class RecordingReader {
 public:
  // A folder is read as a recording folder, a file as MCAP. Reads every
  // set's metadata (not its images). Throws std::runtime_error naming the
  // path if it is not a recording, holds no image sets, or is corrupt.
  static std::unique_ptr<RecordingReader> open(const std::string& path);
  virtual ~RecordingReader() = default;

  virtual std::size_t size() const = 0;  // sets, in recording order
  // Set i's metadata (frames empty; stamps, ids and depths filled).
  virtual const pipeline::ImageSet& info(std::size_t i) const = 0;
  // Set i with its frames. Throws std::runtime_error naming where() on a
  // missing or unreadable frame.
  virtual pipeline::ImageSet load(std::size_t i) const = 0;
  // Where set i is, for messages: its folder, or "<file>: image set k (message n)".
  virtual std::string where(std::size_t i) const = 0;
  // Where frame `frame` of camera `camera` of set i is: its PNG file, or
  // "<file>: image set k (message n): camera 'c' image f".
  virtual std::string whereFrame(std::size_t i, const std::string& camera, std::size_t frame) const = 0;
};

}  // namespace sl::drivers
