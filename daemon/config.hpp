#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/frame.hpp"
#include "hal/laser_channel.hpp"
#include "hal/yaml_reader.hpp"
#include "pipeline/detector.hpp"

namespace laserline::daemon {

enum class LaserMode : std::uint8_t { kOn, kAlternate, kOff, kPattern };

// laser.mode's names: "on", "alternate", "off", "pattern"; from_name false for any other.
const char* to_string(LaserMode mode);
bool laser_mode_from_name(const std::string& name, LaserMode* mode);

// lcm.command_token: at most this long (a command's strings fit the checked decode's limit).
inline constexpr std::size_t kMaxCommandTokenBytes = 255;

enum class ImageCompression : std::uint8_t { kNone, kZlib, kPng, kJpeg };

// What goes out on the raw frame channel: which frames, which part, how packed.
struct RawFrameOptions {
  int every_n = 30;          // every n-th processed frame; 0 = none
  double max_rate_hz = 0;    // and at most this often; 0 = no limit
  int roi_x = 0, roi_y = 0;  // region of interest in full-frame pixels;
  int roi_width = 0;         // 0 = the whole frame
  int roi_height = 0;
  // Defaults: half size, JPEG, about 60 kB a frame: arrives whole at a subscriber with a stock
  // UDP receive buffer (net.core.rmem_default 208 kB), which a 1.3 MB raw frame does not.
  int downscale = 2;  // 1, 2 or 4: mean of each downscale x downscale block
  ImageCompression compression = ImageCompression::kJpeg;
  int jpeg_quality = 90;
  int zlib_level = 1;  // fast: the image thread must keep up at full size
};

// Where a calibration was read from, for messages: the file, and the key of its laser section
// there ("laser" in a calibration file of its own, "calibration.laser" inline in a configuration).
struct CalibrationSource {
  std::string file;
  std::string laser_key = "laser";
};

struct DaemonConfig {
  std::string source;  // where it was read from (a path, or "built-in default")

  std::string camera_backend = "sim";
  double frame_rate_hz = 30.0;
  int grab_timeout_ms = 1000;
  // camera.channel: the laser's light in colour frames (weights of red, green, blue), handed to
  // the camera backend, which converts its frames with it.
  hal::LaserChannel laser_channel;
  // The `camera:` section with the keys above read; the backend reads the rest when created.
  hal::YamlMap camera_options;

  hal::Calibration calibration;
  CalibrationSource calibration_source;

  std::string laser_backend = "sim";
  LaserMode laser_mode = LaserMode::kOn;
  std::vector<bool> laser_pattern;  // kPattern: frame n has the laser on when [n % size] is set
  int laser_frame_timeout_ms = 300;
  hal::YamlMap laser_options;  // likewise for the laser backend

  std::string detector = "background";  // the paper's front-end; as in the built-in file
  pipeline::DetectorOptions detector_options;

  bool realtime = false;  // SCHED_FIFO per daemon/thread_priorities.hpp, memory locked
  std::vector<int> cpus;  // CPU affinity of the frame-path threads; empty = any

  int frame_slots = 8;
  // Threads that share each frame's detection (the worker and worker_threads - 1 helpers).
  int worker_threads = 1;
  int profile_slots = 16;
  int image_slots = 2;
  // What the frame path may allocate at start (rings, raw-frame and publishing buffers, the
  // detector's own); a configuration needing more is refused before anything starts.
  std::int64_t frame_memory_limit_mb = 1024;

  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  std::string profile_channel = "LASERLINE_PROFILE";
  bool profile_all_points = false;  // lcm.profile_points: all (rejected candidates too) | accepted
  std::string image_channel = "LASERLINE_IMAGE";
  std::string status_channel = "LASERLINE_STATUS";
  std::string calibration_channel = "LASERLINE_CALIBRATION";
  // Settings changed while running (laserline.command_t), answered on command_ack_channel
  // (default: command_channel + "_ACK"); a command must carry command_token when one is set.
  std::string command_channel = "LASERLINE_COMMAND";
  std::string command_ack_channel = "LASERLINE_COMMAND_ACK";
  std::string command_token;
  int image_every_n = 30;  // = raw_frames.every_n, kept for the existing readers
  RawFrameOptions raw_frames;
  double status_period_s = 1.0;
  double calibration_period_s = 5.0;  // laserline.calibration_t: at start and this often
};

// Reads the options of every detector from the `detector:` section (all keys but `name`).
void read_detector_options(hal::YamlMap& detector, pipeline::DetectorOptions& options);
// The pipeline's view of a calibration.
pipeline::ScannerGeometry scanner_geometry(const hal::Calibration& calibration);

// Whether the camera can see the laser sheet at all, checked once before any frame, whichever way
// the line runs in the image: throws hal::ConfigError ("FILE: laser...: what is wrong") when the
// sheet passes through the camera centre or lies behind the camera at every pixel (nothing could be
// triangulated), or, given a `depth_range` (the front-end's, read from `depth_range_source`), when
// no pixel sees the sheet between its min_depth_m and max_depth_m (nothing would be searched).
void check_laser_sheet_in_view(const hal::Calibration& calibration,
                               const CalibrationSource& calibration_source,
                               const pipeline::FrontendOptions* depth_range,
                               const std::string& depth_range_source);
// The depths (metres) at which the camera sees the laser sheet: from the nearest pixel's to the
// farthest's, infinity where the horizon is in view; nearest <= 0 when the sheet lies behind the
// camera at every pixel.
struct DepthsSeen {
  double nearest, farthest;
};
DepthsSeen depths_seen(const hal::Calibration& calibration);
// Whether a detector searches only where the sheet lies within the front-end's depth range (all
// but maxvalue, which takes each line's brightest pixel wherever it is).
bool searches_depth_range(const std::string& detector);

// Memory the frame path allocates at start for frames of `format` with at most `max_points` points
// each: the frame, profile and raw-frame rings, the publisher's and the raw-frame encoder's
// buffers and the latency windows; the detector's own buffers not included. Saturates at the
// largest value instead of overflowing.
std::uint64_t frame_path_memory_bytes(const DaemonConfig& config, const hal::FrameFormat& format,
                                      std::size_t max_points);

// Everything the start checks once the camera's format is known, run by create_backends() so that
// a configuration --check-config passes starts: the camera's frames have the calibration's size
// and hold lcm.image_roi at lcm.image_downscale, the frame path's memory fits
// pipeline.frame_memory_limit_mb, and the detector takes frames of that size (its reset(), which
// refuses a frame too small for it and sizes its buffers, whose memory is counted in the limit
// too). Throws hal::ConfigError naming the configuration and the key.
void check_frame_path(const DaemonConfig& config, const hal::FrameFormat& format,
                      pipeline::Detector& detector);

// The region a frame of `format` is cut to: the whole frame when none is given.
RawFrameOptions with_raw_frame_region(RawFrameOptions options, const hal::FrameFormat& format);
// Why `options` cannot be applied to frames of `format` ("lcm.image_roi: ..." or
// "lcm.image_downscale: ..."), or "" when they can: the region must lie inside the frame (in
// 64-bit arithmetic) and hold at least one downscaled pixel.
std::string raw_frame_region_problem(const RawFrameOptions& options,
                                     const hal::FrameFormat& format);
// Bytes a RawFrameEncoder for `options` and `format` allocates.
std::uint64_t raw_frame_encoder_bytes(const RawFrameOptions& options,
                                      const hal::FrameFormat& format);

// The configuration compiled into the daemon (config/laserline.yaml).
const char* builtin_config_text();

// Parses and validates a configuration; throws hal::ConfigError ("FILE:LINE: KEY: problem").
// Keys the file leaves out take their defaults. Backend-specific options are validated
// when the backends are created (also before any hardware is touched).
DaemonConfig parse_config(const YAML::Node& root, const std::string& source);
DaemonConfig load_config_file(const std::string& path);
DaemonConfig builtin_config();

}  // namespace laserline::daemon
