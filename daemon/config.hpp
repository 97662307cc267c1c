#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/yaml_reader.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

enum class LaserMode : std::uint8_t { kOn, kAlternate, kOff, kPattern };

struct DaemonConfig {
  std::string source;  // where it was read from (a path, or "built-in default")

  std::string camera_backend = "sim";
  double frame_rate_hz = 30.0;
  int grab_timeout_ms = 1000;
  // The `camera:` section with the keys above read; the backend reads the rest when created.
  hal::YamlMap camera_options;

  hal::Calibration calibration;

  std::string laser_backend = "sim";
  LaserMode laser_mode = LaserMode::kOn;
  std::vector<bool> laser_pattern;  // kPattern: frame n has the laser on when [n % size] is set
  int laser_frame_timeout_ms = 300;
  hal::YamlMap laser_options;  // likewise for the laser backend

  std::string detector = "maxvalue";
  pipeline::DetectorOptions detector_options;

  bool realtime = false;  // SCHED_FIFO per daemon/thread_priorities.hpp, memory locked
  std::vector<int> cpus;  // CPU affinity of the frame-path threads; empty = any

  int frame_slots = 8;
  int profile_slots = 16;
  int image_slots = 2;

  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  std::string profile_channel = "LASERLINE_PROFILE";
  std::string image_channel = "LASERLINE_IMAGE";
  std::string status_channel = "LASERLINE_STATUS";
  int image_every_n = 30;
  double status_period_s = 1.0;
};

// The configuration compiled into the daemon (config/laserline.yaml).
const char* builtin_config_text();

// Parses and validates a configuration; throws hal::ConfigError ("FILE:LINE: KEY: problem").
// Keys the file leaves out take their defaults. Backend-specific options are validated
// when the backends are created (also before any hardware is touched).
DaemonConfig parse_config(const YAML::Node& root, const std::string& source);
DaemonConfig load_config_file(const std::string& path);
DaemonConfig builtin_config();

}  // namespace laserline::daemon
