#include "sl/files/input_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sstream>

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/anchor.h>

#include "sl/files/config_error.h"

namespace sl::files {

const char* inputKindName(InputKind kind) {
  switch (kind) {
    case InputKind::kConfig: return "config file";
    case InputKind::kPattern: return "pattern file";
    case InputKind::kCalibration: return "calibration file";
    case InputKind::kProjectorResponse: return "projector response file";
    case InputKind::kMesh: return "mesh file";
    case InputKind::kTexture: return "texture file";
    case InputKind::kRecordingIndex: return "recording index file";
    case InputKind::kRecordingFrame: return "recording frame";
  }
  return "file";
}

std::uintmax_t inputSizeLimit(InputKind kind) {
  constexpr std::uintmax_t kMiB = 1 << 20;
  switch (kind) {
    case InputKind::kConfig: return 1 * kMiB;
    case InputKind::kPattern: return 1 * kMiB;
    case InputKind::kCalibration: return 16 * kMiB;
    case InputKind::kProjectorResponse: return 4 * kMiB;
    case InputKind::kMesh: return 512 * kMiB;
    case InputKind::kTexture: return 256 * kMiB;
    case InputKind::kRecordingIndex: return 1 * kMiB;
    case InputKind::kRecordingFrame: return 64 * kMiB;
  }
  return kMiB;
}

namespace {

[[noreturn]] void refuse(const std::string& path, InputKind kind, const std::string& why) {
  throw ConfigError(path + ": " + why + " (" + inputKindName(kind) + ")");
}

// An open descriptor of a checked regular file; closed on scope exit.
struct CheckedFile {
  int fd = -1;
  std::uintmax_t bytes = 0;
  ~CheckedFile() {
    if (fd >= 0) ::close(fd);
  }
};

void openChecked(const std::string& path, InputKind kind, CheckedFile& file) {
  // O_NONBLOCK: opening a FIFO without a writer returns at once instead of
  // waiting; fstat below then refuses it before any read.
  file.fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (file.fd < 0) refuse(path, kind, std::string("cannot open: ") + std::strerror(errno));
  struct stat st {};
  if (::fstat(file.fd, &st) != 0) refuse(path, kind, std::string("cannot stat: ") + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) refuse(path, kind, "is a directory, not a regular file");
  if (S_ISFIFO(st.st_mode)) refuse(path, kind, "is a FIFO, not a regular file");
  if (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode)) refuse(path, kind, "is a device, not a regular file");
  if (!S_ISREG(st.st_mode)) refuse(path, kind, "is not a regular file");
  file.bytes = static_cast<std::uintmax_t>(st.st_size);
  if (file.bytes > inputSizeLimit(kind))
    refuse(path, kind, "is " + std::to_string(file.bytes) + " bytes, more than the limit of " +
                           std::to_string(inputSizeLimit(kind)));
}

// Counts what a document would expand to before yaml-cpp builds it.
class YamlLimits : public YAML::EventHandler {
 public:
  explicit YamlLimits(std::string origin) : origin_(std::move(origin)) {}
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t anchor) override { node(mark, anchor); }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override {
    if (++aliases_ > kMaxYamlAliases)
      fail(mark, "more than " + std::to_string(kMaxYamlAliases) + " aliases (*name)");
  }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                const std::string&) override {
    node(mark, anchor);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                       YAML::EmitterStyle::value) override {
    open(mark, anchor);
  }
  void OnSequenceEnd() override { --depth_; }
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                  YAML::EmitterStyle::value) override {
    open(mark, anchor);
  }
  void OnMapEnd() override { --depth_; }

 private:
  [[noreturn]] void fail(const YAML::Mark& mark, const std::string& why) const {
    throw ConfigError(origin_ + ":" + std::to_string(mark.line + 1) + ": " + why);
  }
  void node(const YAML::Mark& mark, YAML::anchor_t anchor) {
    if (anchor != YAML::NullAnchor && ++anchors_ > kMaxYamlAnchors)
      fail(mark, "more than " + std::to_string(kMaxYamlAnchors) + " anchors (&name)");
  }
  void open(const YAML::Mark& mark, YAML::anchor_t anchor) {
    node(mark, anchor);
    if (++depth_ > kMaxYamlDepth)
      fail(mark, "nested more than " + std::to_string(kMaxYamlDepth) + " levels deep");
  }
  std::string origin_;
  int aliases_ = 0, anchors_ = 0, depth_ = 0;
};

}  // namespace

std::uintmax_t checkInputFile(const std::string& path, InputKind kind) {
  CheckedFile file;
  openChecked(path, kind, file);
  return file.bytes;
}

std::string readInputFile(const std::string& path, InputKind kind) {
  CheckedFile file;
  openChecked(path, kind, file);
  // A regular file never blocks; read at most one byte past the limit in
  // case it grows meanwhile.
  const std::uintmax_t limit = inputSizeLimit(kind);
  std::string text;
  text.reserve(static_cast<std::size_t>(file.bytes));
  char buffer[65536];
  while (true) {
    const ssize_t n = ::read(file.fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) refuse(path, kind, std::string("cannot read: ") + std::strerror(errno));
    if (n == 0) break;
    text.append(buffer, static_cast<std::size_t>(n));
    if (text.size() > limit)
      refuse(path, kind, "grew past the limit of " + std::to_string(limit) + " bytes while read");
  }
  return text;
}

YAML::Node parseInputYaml(const std::string& text, const std::string& origin) {
  try {
    std::istringstream in(text);
    YAML::Parser parser(in);
    YamlLimits limits(origin);
    int documents = 0;
    while (parser.HandleNextDocument(limits)) {
      if (++documents > 1)
        throw ConfigError(origin + ": holds more than one YAML document ('---'); one per file");
    }
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
}

YAML::Node loadInputYaml(const std::string& path, InputKind kind) {
  return parseInputYaml(readInputFile(path, kind), path);
}

}  // namespace sl::files
