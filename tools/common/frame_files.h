// The frame files of a capture folder, in projection order, or refused: a
// capture whose order cannot be told from its file names is an error, never
// a guess (a wrong order decodes to points off by whole periods).
#pragma once

#include <string>
#include <vector>

namespace sl::tools {

// a < b in natural order: runs of digits compare by their value (x_2 < x_10),
// everything else byte by byte; equal values of different padding (x_1,
// x_01) compare by length, so the order is total.
bool naturalLess(const std::string& a, const std::string& b);

// Image files of `dir` (png, bmp, tif, tiff, pgm, jpg, jpeg;
// case-insensitive extension) in natural order of their names. Throws
// std::runtime_error naming the folder when it cannot be read, when the
// names do not all follow one numbering (same text around the numbers, e.g.
// frame_#.png; white.png beside frame_00.png is refused), or when two names
// carry the same number (x_1.png and x_01.png): the message asks for --list.
std::vector<std::string> listFrameFiles(const std::string& dir);

// The files named one per line in `list_path` (blank lines and lines starting
// with '#' ignored), relative ones resolved against `dir`. Throws
// std::runtime_error naming the list and line when the list cannot be read,
// a file does not exist, or a file is listed twice.
std::vector<std::string> readFrameList(const std::string& list_path, const std::string& dir);

}  // namespace sl::tools
