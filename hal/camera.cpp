#include "hal/camera.hpp"

#include <cmath>
#include <cstdarg>
#include <sstream>

namespace laserline::hal {

const char* to_string(GrabStatus status) {
  switch (status) {
    case GrabStatus::kOk:
      return "ok";
    case GrabStatus::kTimeout:
      return "timeout";
    case GrabStatus::kError:
      return "error";
    case GrabStatus::kStopped:
      return "stopped";
  }
  return "unknown";
}

std::string range_problem(const char* name, const char* text, double value, NumberRange range) {
  if (!std::isfinite(value)) return std::string(name) + ": must be a number, got '" + text + "'";
  if (range.holds(value)) return "";
  std::ostringstream out;
  out << name << ": must be between " << range.min << " and " << range.max << ", got " << text;
  return out.str();
}

void write_setting_value(std::span<char> out, double value) {
  if (out.empty()) return;
  std::snprintf(out.data(), out.size(), "%.7g", value);
}

void write_setting_text(std::span<char> out, const char* text) {
  if (out.empty()) return;
  std::snprintf(out.data(), out.size(), "%s", text != nullptr ? text : "");
}

void write_setting_line(std::span<char> out, const char* format, ...) {
  if (out.empty()) return;
  va_list args;
  va_start(args, format);
  std::vsnprintf(out.data(), out.size(), format, args);
  va_end(args);
}

}  // namespace laserline::hal
