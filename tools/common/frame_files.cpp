#include "common/frame_files.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>

namespace sl::tools {

namespace fs = std::filesystem;

namespace {

bool isDigit(char c) { return c >= '0' && c <= '9'; }

// The name with every run of digits replaced by '#', and the runs' values
// (leading zeros stripped).
std::pair<std::string, std::vector<std::string>> numbering(const std::string& name) {
  std::string skeleton;
  std::vector<std::string> numbers;
  for (std::size_t i = 0; i < name.size();) {
    if (!isDigit(name[i])) {
      skeleton += name[i++];
      continue;
    }
    std::size_t j = i;
    while (j < name.size() && isDigit(name[j])) ++j;
    std::size_t k = i;
    while (k + 1 < j && name[k] == '0') ++k;
    numbers.push_back(name.substr(k, j - k));
    skeleton += '#';
    i = j;
  }
  return {skeleton, numbers};
}

}  // namespace

bool naturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (isDigit(a[i]) && isDigit(b[j])) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && isDigit(a[ie])) ++ie;
      while (je < b.size() && isDigit(b[je])) ++je;
      std::size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      const std::size_t la = ie - is, lb = je - js;
      if (la != lb) return la < lb;
      const int c = a.compare(is, la, b, js, lb);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;  // x_1 before x_01
      i = ie;
      j = je;
      continue;
    }
    if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
    ++i;
    ++j;
  }
  return a.size() - i < b.size() - j;
}

std::vector<std::string> listFrameFiles(const std::string& dir) {
  static const std::set<std::string> kExtensions = {".png", ".bmp", ".tif", ".tiff",
                                                    ".pgm", ".jpg", ".jpeg"};
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  if (ec) throw std::runtime_error(dir + ": cannot read folder: " + ec.message());
  std::vector<std::string> names;
  for (const fs::directory_entry& e : it) {
    if (!e.is_regular_file()) continue;
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (kExtensions.count(ext)) names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end(), naturalLess);
  // One numbering for all, and each number once.
  std::map<std::string, std::vector<std::string>> by_skeleton;
  std::map<std::pair<std::string, std::vector<std::string>>, std::string> seen;
  for (const std::string& n : names) {
    auto key = numbering(n);
    by_skeleton[key.first].push_back(n);
    const auto [at, fresh] = seen.emplace(key, n);
    if (!fresh)
      throw std::runtime_error(dir + ": '" + at->second + "' and '" + n +
                               "' carry the same number: the frame order is ambiguous; give it "
                               "with --list FILE (one file name per line, in projection order)");
  }
  if (by_skeleton.size() > 1) {
    std::string kinds;
    for (const auto& [skeleton, files] : by_skeleton)
      kinds += (kinds.empty() ? "" : ", ") + std::string("'") + files.front() + "'" +
               (files.size() > 1 ? " (" + std::to_string(files.size()) + " like it)" : "");
    throw std::runtime_error(dir + ": the image names follow no single numbering (" + kinds +
                             "): the frame order cannot be told from them; give it with --list "
                             "FILE (one file name per line, in projection order)");
  }
  std::vector<std::string> files;
  for (const std::string& n : names) files.push_back((fs::path(dir) / n).string());
  return files;
}

std::vector<std::string> readFrameList(const std::string& list_path, const std::string& dir) {
  std::ifstream list(list_path);
  if (!list) throw std::runtime_error(list_path + ": cannot open the frame list");
  std::vector<std::string> files;
  std::map<std::string, int> lines;
  int number = 0;
  for (std::string line; std::getline(list, line);) {
    ++number;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const fs::path p(line);
    const std::string path = (p.is_relative() ? fs::path(dir) / p : p).string();
    const std::string where = list_path + ":" + std::to_string(number) + ": ";
    if (!fs::is_regular_file(path)) throw std::runtime_error(where + path + ": no such file");
    const std::string canonical = fs::weakly_canonical(path).string();
    const auto [at, fresh] = lines.emplace(canonical, number);
    if (!fresh)
      throw std::runtime_error(where + "'" + line + "' is listed twice (also on line " +
                               std::to_string(at->second) + ")");
    files.push_back(path);
  }
  if (files.empty()) throw std::runtime_error(list_path + ": the frame list names no files");
  return files;
}

}  // namespace sl::tools
