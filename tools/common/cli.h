// Command-line value parsing shared by the tools: the whole text must be the
// number (no trailing characters); nullopt otherwise. Each tool words its own
// usage error.
#pragma once

#include <optional>
#include <string>

namespace sl::tools {

inline std::optional<double> toNumber(const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

inline std::optional<int> toInt(const std::string& text) {
  try {
    std::size_t used = 0;
    const int v = std::stoi(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

}  // namespace sl::tools
