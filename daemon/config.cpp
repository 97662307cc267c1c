#include "daemon/config.hpp"

#include <filesystem>

namespace laserline::daemon {

namespace {

int power_of_two(hal::YamlMap& map, const std::string& key, int fallback) {
  const auto value = static_cast<int>(map.integer(key, fallback, 2, 1024));
  if ((value & (value - 1)) != 0)
    map.fail(key, "must be a power of two, got " + std::to_string(value));
  return value;
}

hal::Calibration read_calibration_section(hal::YamlMap& root, const std::string& source) {
  if (root.has("calibration")) {
    YAML::Node node = root.node("calibration");
    if (node.IsScalar()) {
      // A path, relative to the configuration file.
      std::filesystem::path path = node.Scalar();
      if (path.is_relative() && source.find('/') != std::string::npos) {
        path = std::filesystem::path(source).parent_path() / path;
      }
      return hal::load_calibration_file(path.string());
    }
  }
  hal::YamlMap section = root.map("calibration");
  hal::Calibration calibration = hal::read_calibration(section);
  section.finish();
  return calibration;
}

}  // namespace

DaemonConfig parse_config(const YAML::Node& root_node, const std::string& source) {
  DaemonConfig c;
  c.source = source;
  hal::YamlMap root(root_node, source, "");

  hal::YamlMap camera = root.map("camera");
  c.camera_backend = camera.string("backend", c.camera_backend);
  c.frame_rate_hz = camera.number("frame_rate_hz", c.frame_rate_hz, 0.1, 1000.0);
  c.grab_timeout_ms = static_cast<int>(camera.integer("timeout_ms", c.grab_timeout_ms, 10, 60000));
  // The backend reads the rest of the section (and rejects unknown keys) when it is created.
  c.camera_options = camera;

  c.calibration = read_calibration_section(root, source);

  hal::YamlMap laser = root.map("laser");
  c.laser_backend = laser.string("backend", c.laser_backend);
  const std::string mode = laser.choice("mode", "on", {"on", "alternate", "off", "pattern"});
  c.laser_mode = mode == "on"          ? LaserMode::kOn
                 : mode == "off"       ? LaserMode::kOff
                 : mode == "alternate" ? LaserMode::kAlternate
                                       : LaserMode::kPattern;
  if (c.laser_mode == LaserMode::kPattern) {
    if (!laser.has("pattern")) {
      laser.fail("pattern", "required with mode: pattern, e.g. \"110\" (on, on, off, repeated)");
    }
    const std::string pattern = laser.string("pattern", "");
    if (pattern.empty() || pattern.size() > 1024 ||
        pattern.find_first_not_of("01") != std::string::npos) {
      laser.fail("pattern",
                 "must be 1 to 1024 characters 0 (off) or 1 (on), got '" + pattern + "'");
    }
    for (char bit : pattern)
      c.laser_pattern.push_back(bit == '1');
  } else if (laser.has("pattern")) {
    laser.fail("pattern", "only used with mode: pattern");
  }
  c.laser_frame_timeout_ms =
      static_cast<int>(laser.integer("frame_timeout_ms", c.laser_frame_timeout_ms, 10, 10000));
  c.laser_options = laser;

  hal::YamlMap detector = root.map("detector");
  c.detector = detector.choice("name", c.detector, pipeline::detector_names());
  hal::YamlMap maxvalue = detector.map("maxvalue");
  c.detector_options.maxvalue_threshold = static_cast<int>(
      maxvalue.integer("threshold", c.detector_options.maxvalue_threshold, 1, 255));
  maxvalue.finish();
  detector.finish();

  hal::YamlMap realtime = root.map("realtime");
  c.realtime = realtime.boolean("enabled", c.realtime);
  for (double cpu : realtime.numbers("cpus", {1, 2, 3, 4, 5, 6, 7, 8})) {
    if (cpu != static_cast<int>(cpu) || cpu < 0 || cpu > 1023) {
      realtime.fail("cpus", "must list CPU numbers 0..1023");
    }
    c.cpus.push_back(static_cast<int>(cpu));
  }
  realtime.finish();

  hal::YamlMap pipe = root.map("pipeline");
  c.frame_slots = power_of_two(pipe, "frame_slots", c.frame_slots);
  c.profile_slots = power_of_two(pipe, "profile_slots", c.profile_slots);
  c.image_slots = power_of_two(pipe, "image_slots", c.image_slots);
  pipe.finish();

  hal::YamlMap lcm = root.map("lcm");
  c.lcm_url = lcm.string("url", c.lcm_url);
  if (c.lcm_url.empty()) lcm.fail("url", "must not be empty");
  const std::string provider = c.lcm_url.substr(0, c.lcm_url.find("://"));
  if (c.lcm_url.find("://") == std::string::npos ||
      (provider != "udpm" && provider != "memq" && provider != "file" && provider != "tcpq")) {
    lcm.fail("url", "must be udpm://, memq://, file:// or tcpq://, got '" + c.lcm_url + "'");
  }
  for (auto [key, channel] : {std::pair{"profile_channel", &c.profile_channel},
                              std::pair{"image_channel", &c.image_channel},
                              std::pair{"status_channel", &c.status_channel}}) {
    *channel = lcm.string(key, *channel);
    // LCM carries channel names in the packet header, which caps them at 63 bytes.
    if (channel->empty() || channel->size() > 63) lcm.fail(key, "must be 1 to 63 characters");
  }
  c.image_every_n = static_cast<int>(lcm.integer("image_every_n", c.image_every_n, 0, 1000000));
  c.status_period_s = lcm.number("status_period_s", c.status_period_s, 0.05, 3600.0);
  lcm.finish();

  root.finish();
  return c;
}

DaemonConfig load_config_file(const std::string& path) {
  return parse_config(hal::load_yaml_file(path), path);
}

DaemonConfig builtin_config() {
  return parse_config(hal::load_yaml_text(builtin_config_text(), "built-in default"),
                      "built-in default");
}

}  // namespace laserline::daemon
