#include "sl/dds/environment.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace sl::dds {

namespace {

// "8MiB", "65000B", "64 KB", "1048576" -> bytes; nullopt for "default" or
// anything Cyclone would not read as a size.
std::optional<std::int64_t> parseSize(std::string text) {
  text.erase(std::remove_if(text.begin(), text.end(), [](unsigned char c) { return std::isspace(c); }),
             text.end());
  std::size_t digits = 0;
  while (digits < text.size() && (std::isdigit(static_cast<unsigned char>(text[digits])) || text[digits] == '.'))
    ++digits;
  if (digits == 0) return std::nullopt;
  const double value = std::stod(text.substr(0, digits));
  std::string unit = text.substr(digits);
  std::transform(unit.begin(), unit.end(), unit.begin(), [](unsigned char c) { return std::tolower(c); });
  double scale = 0;
  if (unit.empty() || unit == "b") scale = 1;
  else if (unit == "kb") scale = 1e3;
  else if (unit == "kib") scale = 1024.0;
  else if (unit == "mb") scale = 1e6;
  else if (unit == "mib") scale = 1024.0 * 1024;
  else if (unit == "gb") scale = 1e9;
  else if (unit == "gib") scale = 1024.0 * 1024 * 1024;
  else return std::nullopt;
  return static_cast<std::int64_t>(value * scale);
}

void keepLarger(std::optional<std::int64_t>& into, std::optional<std::int64_t> v) {
  if (v && (!into || *v > *into)) into = v;
}

// The largest max= (or, without max=, the element's text) of every <element ...>.
std::optional<std::int64_t> largestSize(const std::string& xml, const std::string& element) {
  std::optional<std::int64_t> best;
  const std::regex tag("<" + element + "\\b([^>]*?)(/>|>([^<]*)</" + element + ">)");
  const std::regex max_attr("\\bmax\\s*=\\s*\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), tag); it != std::sregex_iterator(); ++it) {
    const std::string attributes = (*it)[1];
    std::smatch m;
    if (std::regex_search(attributes, m, max_attr))
      keepLarger(best, parseSize(m[1]));
    else if ((*it)[3].matched)
      keepLarger(best, parseSize((*it)[3]));
  }
  return best;
}

std::string withoutComments(const std::string& xml) {
  return std::regex_replace(xml, std::regex("<!--[\\s\\S]*?-->"), "");
}

// Every IPv4 address (dotted quad) given as attribute address= of <element>,
// or as the text of <text_element>, that is not yet in `into`.
void addIpv4(std::vector<std::string>& into, const std::string& xml, const std::string& element,
             const std::string& text_element = "") {
  const std::regex quad("^\\s*(\\d{1,3}(\\.\\d{1,3}){3})\\s*$");
  auto add = [&](const std::string& value) {
    std::smatch m;
    if (std::regex_match(value, m, quad) && std::find(into.begin(), into.end(), m[1]) == into.end())
      into.push_back(m[1]);
  };
  const std::regex tag("<" + element + "\\b[^>]*?\\baddress\\s*=\\s*\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), tag); it != std::sregex_iterator(); ++it)
    add((*it)[1]);
  if (text_element.empty()) return;
  const std::regex text("<" + text_element + ">([^<]*)</" + text_element + ">");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), text); it != std::sregex_iterator(); ++it)
    add((*it)[1]);
}

std::string mib(std::int64_t bytes) {
  std::ostringstream out;
  out.precision(bytes % (1 << 20) == 0 ? 0 : 1);
  out << std::fixed << bytes / double(1 << 20) << " MiB";
  return out.str();
}

std::int64_t readNumber(const std::string& path) {
  std::ifstream in(path);
  std::int64_t v = 0;
  return in >> v ? v : 0;
}

}  // namespace

DdsRequirements readDdsRequirements(const std::string& uri) {
  DdsRequirements r;
  std::vector<std::string> parts;
  const std::string trimmed = uri.substr(std::min(uri.find_first_not_of(" \t\n"), uri.size()));
  if (!trimmed.empty() && trimmed.front() == '<') {
    parts.push_back(trimmed);
  } else {
    std::stringstream list(uri);
    for (std::string item; std::getline(list, item, ',');) {
      item.erase(0, std::min(item.find_first_not_of(" \t\n"), item.size()));
      item.erase(item.find_last_not_of(" \t\n") + 1);
      if (!item.empty()) parts.push_back(item);
    }
  }
  for (const std::string& part : parts) {
    std::string xml;
    if (part.front() == '<') {
      xml = part;
      r.sources.push_back("inline XML");
    } else {
      const std::string path = part.rfind("file://", 0) == 0 ? part.substr(7) : part;
      std::ifstream in(path);
      if (!in) throw std::runtime_error("CYCLONEDDS_URI: cannot read '" + path + "'");
      std::ostringstream text;
      text << in.rdbuf();
      xml = text.str();
      r.sources.push_back(path);
    }
    xml = withoutComments(xml);
    keepLarger(r.receive_buffer_bytes, largestSize(xml, "SocketReceiveBufferSize"));
    keepLarger(r.send_buffer_bytes, largestSize(xml, "SocketSendBufferSize"));
    std::smatch m;
    const std::regex shm("<SharedMemory\\b[^>]*>[\\s\\S]*?<Enable>\\s*(true|false)\\s*</Enable>");
    if (std::regex_search(xml, m, shm) && m[1] == "true") r.shared_memory = true;
    addIpv4(r.interface_addresses, xml, "NetworkInterface", "NetworkInterfaceAddress");
    addIpv4(r.peer_addresses, xml, "Peer");
    if (std::regex_search(xml, std::regex("<AllowMulticast>\\s*false\\s*</AllowMulticast>")))
      r.allow_multicast = false;
    if (std::regex_search(xml, std::regex("<(DDS)?Security\\b"))) r.security = true;
  }
  return r;
}

DdsHost currentDdsHost() {
  DdsHost h;
  h.rmem_max = readNumber("/proc/sys/net/core/rmem_max");
  h.wmem_max = readNumber("/proc/sys/net/core/wmem_max");
  struct stat st {};
  h.roudi_running = ::stat("/tmp/roudi", &st) == 0;
  return h;
}

std::vector<std::string> ddsEnvironmentProblems(const DdsRequirements& wanted, const DdsHost& host) {
  std::vector<std::string> lines;
  const std::string source = wanted.sources.empty() ? "the DDS configuration" : wanted.sources.front();
  const std::string fix =
      "install systemd/99-sl-sensor-sysctl.conf (cp systemd/99-sl-sensor-sysctl.conf "
      "/etc/sysctl.d/ && sysctl --system)";
  if (wanted.receive_buffer_bytes && host.rmem_max > 0 && *wanted.receive_buffer_bytes > host.rmem_max)
    lines.push_back(source + " asks for a " + mib(*wanted.receive_buffer_bytes) +
                    " socket receive buffer but net.core.rmem_max is " + mib(host.rmem_max) +
                    ": clouds over UDP lose datagrams and wait for repairs; " + fix);
  if (wanted.send_buffer_bytes && host.wmem_max > 0 && *wanted.send_buffer_bytes > host.wmem_max)
    lines.push_back(source + " asks for a " + mib(*wanted.send_buffer_bytes) +
                    " socket send buffer but net.core.wmem_max is " + mib(host.wmem_max) + "; " + fix);
  if (wanted.shared_memory && !host.roudi_running)
    lines.push_back(source +
                    " enables shared memory but no iceoryx RouDi is running (no /tmp/roudi): "
                    "Cyclone waits 60 s for it, then aborts; start it first (systemctl start "
                    "iceoryx-roudi, or iox-roudi -c config/iceoryx-roudi.toml)");
  return lines;
}

}  // namespace sl::dds
