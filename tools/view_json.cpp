#include "tools/view_json.hpp"

#include <cmath>
#include <cstdio>

namespace laserline::view {

void append_string(std::string& out, const std::string& text) {
  out += '"';
  for (const char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\u%04x", static_cast<unsigned>(c));
      out += escaped;
    } else {
      out += c;
    }
  }
  out += '"';
}

void append_number(std::string& out, double value, int decimals) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  char text[48];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  // "1.500" -> "1.5", "2.000" -> "2": smaller events.
  std::string s = text;
  if (s.find('.') != std::string::npos) {
    while (s.back() == '0')
      s.pop_back();
    if (s.back() == '.') s.pop_back();
  }
  if (s == "-0") s.erase(0, 1);  // a negative zero as 0
  out += s;
}

void append_integer(std::string& out, std::int64_t value) {
  out += std::to_string(value);
}

std::string numbers(const std::vector<float>& values, int decimals) {
  std::string out = "[";
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ',';
    append_number(out, values[i], decimals);
  }
  return out + "]";
}

}  // namespace laserline::view
