#include "daemon/command.hpp"

#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "pipeline/options.hpp"

namespace laserline::daemon {

namespace {

constexpr const char* kCameraNames[] = {"exposure_us", "gain_db", "frame_rate_hz"};
constexpr const char* kCameraPrefixes[] = {"genicam:", "v4l2:"};

bool is_camera_setting(const std::string& name) {
  for (const char* known : kCameraNames) {
    if (name == known) return true;
  }
  for (const char* prefix : kCameraPrefixes) {
    if (name.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

// The whole text as a finite number, or NaN.
double number_of(const std::string& text) {
  if (text.empty()) return NAN;
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(value)) return NAN;
  return value;
}

// "x,y,width,height" (whole numbers) into *region; false when the text is not that.
bool region_of(const std::string& text, pipeline::DetectionRegion* region) {
  int values[4] = {};
  const char* at = text.c_str();
  for (int i = 0; i < 4; ++i) {
    char* end = nullptr;
    errno = 0;
    const long value = std::strtol(at, &end, 10);
    if (end == at || errno != 0 || value < INT_MIN || value > INT_MAX) return false;
    values[i] = static_cast<int>(value);
    at = end;
    if (i < 3 && *at++ != ',') return false;
  }
  if (*at != '\0') return false;
  *region = {values[0], values[1], values[2], values[3]};
  return true;
}

}  // namespace

std::string printable(const std::string& text) {
  std::string out = text;
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return out;
}

const char* threshold_name(const std::string& detector) {
  return detector == "maxvalue" ? "detector.maxvalue.threshold"
                                : "detector.frontend.snr_threshold_db";
}

std::string threshold_value(const std::string& detector, const pipeline::DetectorOptions& options) {
  std::ostringstream out;
  if (detector == "maxvalue") {
    out << options.maxvalue_threshold;
  } else {
    out << options.frontend.snr_threshold_db;
  }
  return out.str();
}

bool parse_command(const laserline::command_t& message, const DaemonConfig& config,
                   const hal::Camera& camera, const pipeline::DetectorOptions& detector_options,
                   Command* out, pipeline::DetectorOptions* options, std::string* reason) {
  auto refuse = [&](const std::string& why) {
    *reason = why;
    return false;
  };
  *out = Command{};
  out->id = message.id;
  hal::write_setting_text(out->sender, printable(message.sender).c_str());
  hal::write_setting_text(out->setting.name, printable(message.name).c_str());
  if (!config.command_token.empty() && message.token != config.command_token) {
    return refuse(message.token.empty() ? "token: missing (lcm.command_token is set)"
                                        : "token: not the daemon's lcm.command_token");
  }
  const std::string& name = message.name;
  Command& c = *out;
  if (name.size() >= sizeof c.setting.name || message.value.size() >= sizeof c.setting.value) {
    return refuse("name or value longer than " + std::to_string(sizeof c.setting.name - 1) +
                  " bytes");
  }
  std::memcpy(c.setting.name, name.c_str(), name.size() + 1);
  std::memcpy(c.setting.value, message.value.c_str(), message.value.size() + 1);
  c.setting.number = number_of(message.value);
  if (name == "get") {
    if (!message.value.empty())
      return refuse("get: takes no value, got '" + printable(message.value) + "'");
    c.kind = CommandKind::kGet;
    return true;
  }
  if (name == "laser.mode") {
    c.kind = CommandKind::kLaserMode;
    if (!laser_mode_from_name(message.value, &c.laser_mode)) {
      return refuse("laser.mode: must be on, alternate, off or pattern, got '" +
                    printable(message.value) + "'");
    }
    if (c.laser_mode == LaserMode::kPattern && config.laser_pattern.empty()) {
      return refuse("laser.mode: pattern needs laser.pattern in the configuration");
    }
    return true;
  }
  if (name == "detector.maxvalue.threshold" || name == "detector.frontend.snr_threshold_db") {
    c.kind = CommandKind::kThreshold;
    if (name != threshold_name(config.detector)) {
      return refuse(name + ": the detector is " + config.detector + ", its threshold is " +
                    threshold_name(config.detector));
    }
    const double v = c.setting.number;
    if (!std::isfinite(v))
      return refuse(name + ": must be a number, got '" + printable(message.value) + "'");
    *options = detector_options;
    try {
      if (config.detector == "maxvalue") {
        if (v != std::floor(v) || std::fabs(v) > 1e6) {
          return refuse(name + ": must be a whole grey level, got '" + printable(message.value) +
                        "'");
        }
        pipeline::validate_maxvalue_threshold(static_cast<int>(v));
        options->maxvalue_threshold = static_cast<int>(v);
      } else {
        options->frontend.snr_threshold_db = v;
        options->frontend.validate();
      }
    } catch (const pipeline::OptionError& e) {
      return refuse(name + ": " + e.problem());
    }
    return true;
  }
  if (name == "detector.roi") {
    c.kind = CommandKind::kRegion;
    if (message.value.empty() || message.value == "full") {
      c.region = {};
      return true;
    }
    if (!region_of(message.value, &c.region)) {
      return refuse(name + ": expected x,y,width,height in pixels (or full), got '" +
                    printable(message.value) + "'");
    }
    const hal::FrameFormat format = camera.format();
    try {
      c.region.validate(format.width, format.height);
    } catch (const pipeline::OptionError& e) {
      return refuse(name + ": " + e.problem());
    }
    return true;
  }
  if (is_camera_setting(name)) {
    c.kind = CommandKind::kCamera;
    const std::string problem = camera.check_setting(c.setting);
    if (!problem.empty()) return refuse(problem);
    return true;
  }
  return refuse("'" + printable(name) +
                "' is not a setting (exposure_us, gain_db, frame_rate_hz, laser.mode, "
                "detector.maxvalue.threshold, detector.frontend.snr_threshold_db, detector.roi, "
                "genicam:<Feature>, v4l2:<control>, get)");
}

}  // namespace laserline::daemon
