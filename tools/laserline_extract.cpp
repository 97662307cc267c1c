// laserline-extract: runs a laserline detector over recorded frames (image files, folders of
// images, videos, LCM logs of laserline.image_t) and writes the laser points to a CSV file, with
// an optional overlay PNG per frame, and optionally the 3-D points of all frames as one PLY point
// cloud (in the camera frame, or fused into the world frame with a pose log). Same calibration,
// configuration and detectors as laserlined.
//
// Single-threaded. Every frame's points are written and flushed before the next frame is read,
// so an interruption or a bad input never loses what was already extracted.
#include <unistd.h>
#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/calibration_message.hpp"
#include "daemon/config.hpp"
#include "hal/calibration.hpp"
#include "hal/laser_channel.hpp"
#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"
#include "pipeline/detector.hpp"
#include "tools/cli.hpp"
#include "tools/frame_channel.hpp"
#include "tools/natural_order.hpp"
#include "tools/point_cloud.hpp"

namespace {

namespace fs = std::filesystem;
using laserline::hal::ConfigError;

constexpr const char* kUsage =
    "usage: laserline-extract [--calib FILE [--override-log-calibration]] [--config FILE]\n"
    "                         --detector NAME [--threshold VALUE]\n"
    "                         [--channel NAME|EXPR] [--roi x,y,w,h] [--mask FILE]\n"
    "                         [--laser-pattern BITS] [--overlay-dir DIR] [--all-candidates]\n"
    "                         [--output points.csv] [--ply cloud.ply [--poses poses.csv]]\n"
    "                         INPUT...\n"
    "  --calib FILE       calibration (camera and laser); images must have its size. Without\n"
    "                     it, the calibration an LCM log carries (laserline.calibration_t, which\n"
    "                     laserlined publishes); with it, a log recorded with another calibration\n"
    "                     (its calibration_t or its profiles' calibration_id) is refused\n"
    "  --override-log-calibration  extract such a log with --calib all the same (a newer\n"
    "                     calibration of the same scanner)\n"
    "  --config FILE      laserlined configuration whose detector options are used\n"
    "                     (default: the built-in configuration)\n"
    "  --detector NAME    detector to run (see the list below)\n"
    "  --threshold VALUE  the detector's threshold in its own unit, instead of the\n"
    "                     configuration's: maxvalue a grey level 1..255 that a line's brightest\n"
    "                     pixel must reach (built-in 40); fir, background, backprojection an\n"
    "                     SNR in dB 0..60 (built-in 6)\n"
    "  --channel NAME|EXPR  the laser's light in colour frames: red, green (default), blue,\n"
    "                     grey, or a weighted sum such as \"red - (green + blue) / 2\" (also\n"
    "                     cancels white light); mono frames are taken as they are\n"
    "  --roi x,y,w,h      keep only points in this rectangle (left column, top row, width,\n"
    "                     height in pixels); the detector still sees the whole frame\n"
    "  --mask FILE        keep only points on non-zero pixels of this image (the frames' size)\n"
    "  --laser-pattern BITS  the laser state of successive frames, 1 on, 0 off, repeated from\n"
    "                     the start of each sequence (folder, video, log, run of image files):\n"
    "                     10 for on/off alternation. Laser-off frames still reach the detector\n"
    "                     (background keeps them as the next frame's background) but give no\n"
    "                     points. LCM logs' own laser states (their profiles) take precedence\n"
    "  --overlay-dir DIR  write DIR/frame_NNNNNN.png per frame: the grey image the detector saw\n"
    "                     with its points (accepted green, rejected red)\n"
    "  --all-candidates   also write rejected candidates (valid = 0)\n"
    "  --output FILE      CSV: frame,source,u,v,x,y,snr_db,segment,valid (source: the image\n"
    "                     file, or the video's frame or the log's event; u the epipolar line and\n"
    "                     v the position along it, x y the frame pixel: for a laser above or\n"
    "                     below the camera u = x the column, v = y the row; beside it, u = y\n"
    "                     the row, v = x the column)\n"
    "  --ply FILE         the valid points of all frames as one point cloud: binary PLY,\n"
    "                     float x y z (metres) and scalar_snr (SNR in dB; CloudCompare shows\n"
    "                     it as the scalar field \"snr\"), for CloudCompare, MeshLab, PCL;\n"
    "                     in the camera frame unless --poses is given\n"
    "  --poses FILE       CSV timestamp,x,y,z,qw,qx,qy,qz (header line allowed): the pose of\n"
    "                     the camera in the world frame (X_world = R(q) X_camera + (x,y,z)),\n"
    "                     timestamps in seconds, increasing. Frames with a time (LCM logs:\n"
    "                     utime) get the pose interpolated at it (position linear, rotation\n"
    "                     slerp); frames without (images, videos) take the row of their frame\n"
    "                     number. The PLY is then in the world frame (float: keep the world\n"
    "                     origin near the scan, e.g. a local frame rather than UTM)\n"
    "  (at least one of --output and --ply)\n"
    "  INPUT              image files (in the order given), folders of images (in natural\n"
    "                     order: 2 before 10), videos (.avi .mp4 .mkv .mov ...), LCM logs of\n"
    "                     laserline.image_t messages (damaged records are skipped, reported\n"
    "                     with their byte offsets, and reading resumes at the next whole event;\n"
    "                     a damaged or cut-short log counts as a failed input: exit status 1)\n"
    "Colour frames: the green channel is used unless --channel; 16-bit frames are scaled to\n"
    "8 bit.\n"
    "Exit status: 0 all frames processed; 1 some input or frame failed (the others are\n"
    "still written); 2 bad arguments, configuration or calibration (nothing read); 3 frames\n"
    "were read but no point was accepted, or more than half of the accepted points had no 3-D\n"
    "point for --ply (the laser sheet of the calibration misses them); 3 before 1.\n";

constexpr const char* kImageExtensions[] = {
    ".png", ".jpg", ".jpeg", ".jpe",  ".tif", ".tiff", ".bmp", ".dib", ".pgm", ".ppm",
    ".pbm", ".pnm", ".pxm",  ".webp", ".jp2", ".ras",  ".sr",  ".exr", ".hdr", ".pic"};
constexpr const char* kVideoExtensions[] = {".avi", ".mp4",  ".m4v", ".mov", ".mkv",  ".webm",
                                            ".mpg", ".mpeg", ".wmv", ".ogv", ".mjpg", ".mjpeg",
                                            ".flv", ".ts",   ".mts", ".3gp", ".h264", ".h265"};

std::string lower_extension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

template <std::size_t N>
bool has_extension(const fs::path& path, const char* const (&extensions)[N]) {
  const std::string ext = lower_extension(path);
  return std::any_of(std::begin(extensions), std::end(extensions),
                     [&](const char* e) { return ext == e; });
}

// LCM log files start every event with this sync word (big-endian), the first at offset 0.
bool is_lcm_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char magic[4] = {};
  if (!in.read(reinterpret_cast<char*>(magic), 4)) return false;
  return magic[0] == 0xED && magic[1] == 0xA1 && magic[2] == 0xDA && magic[3] == 0x01;
}

// A progress line on stderr, only when stderr is a terminal (never in logs or pipes).
class Progress {
 public:
  Progress() : enabled_(isatty(STDERR_FILENO) == 1) {}

  void update(std::size_t input, std::size_t inputs, const std::string& name, double fraction,
              std::int64_t frames) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(100) && fraction < 1.0) return;
    last_ = now;
    constexpr int kWidth = 30;
    fraction = std::clamp(fraction, 0.0, 1.0);
    const int filled = static_cast<int>(fraction * kWidth);
    std::string bar(static_cast<std::size_t>(filled), '#');
    bar.resize(kWidth, '.');
    std::fprintf(stderr, "\r[%s] %3d%% input %zu/%zu %s, %lld frames\033[K", bar.c_str(),
                 static_cast<int>(fraction * 100.0), input, inputs, name.c_str(),
                 static_cast<long long>(frames));
    shown_ = true;
  }
  // Prints one line, keeping the progress line out of its way.
  void message(const std::string& line) {
    clear();
    std::fprintf(stderr, "%s\n", line.c_str());
  }
  void clear() {
    if (shown_) std::fputs("\r\033[K", stderr);
    shown_ = false;
  }

 private:
  bool enabled_;
  bool shown_ = false;
  std::chrono::steady_clock::time_point last_{};
};

struct Options {
  bool override_log_calibration = false;
  std::string calib, config, detector, overlay_dir, output, ply, poses;
  // As given; checked once the calibration and the detector are known.
  std::string threshold, roi, mask;
  laserline::hal::LaserChannel channel;  // the laser's light in colour frames
  std::string laser_pattern;             // as given, for messages
  std::vector<bool> laser_on_pattern;    // empty: every frame the input says nothing of is "on"
  bool all_candidates = false;
  std::vector<std::string> inputs;
};

// Where points are kept: a rectangle, a mask image, or both. Points elsewhere are left out of
// every output; the pixels are not touched (a zeroed border would be a step edge the band-pass
// filter answers with candidates).
class Region {
 public:
  void limit_to(const cv::Rect& rect) { rect_ = rect; }
  void limit_to(const cv::Mat& mask) { mask_ = mask; }  // CV_8UC1, non-zero = kept

  bool contains(const cv::Point2d& at) const {
    if (!rect_ && mask_.empty()) return true;
    if (!std::isfinite(at.x) || !std::isfinite(at.y)) return false;
    const cv::Point pixel(static_cast<int>(std::lround(at.x)), static_cast<int>(std::lround(at.y)));
    if (rect_ && !rect_->contains(pixel)) return false;
    if (mask_.empty()) return true;
    return pixel.x >= 0 && pixel.y >= 0 && pixel.x < mask_.cols && pixel.y < mask_.rows &&
           mask_.at<std::uint8_t>(pixel) != 0;
  }

 private:
  std::optional<cv::Rect> rect_;
  cv::Mat mask_;
};

// Where a point lies in the image: x the column, y the row (through the profile's search axes).
cv::Point2d image_position(const laserline::pipeline::Profile& profile,
                           const laserline::pipeline::ProfilePoint& p) {
  const auto [x, y] = profile.image_point(p);
  return {x, y};
}

// A CSV field as RFC 4180 has it: quoted when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) {
    quoted += c;
    if (c == '"') quoted += '"';
  }
  return quoted + "\"";
}

// Runs the detector on frames and writes what it finds; counts what failed.
class Extractor {
 public:
  // csv, ply and poses may be null (not asked for).
  Extractor(const Options& options, const laserline::hal::Calibration& calibration,
            std::unique_ptr<laserline::pipeline::Detector> detector, const Region& region,
            FILE* csv, laserline::tools::PlyWriter* ply, const laserline::tools::PoseLog* poses)
      : options_(options),
        width_(calibration.camera.width),
        height_(calibration.camera.height),
        detector_(std::move(detector)),
        profile_(detector_->max_points(width_, height_)),
        region_(region),
        csv_(csv),
        ply_(ply),
        poses_(poses) {
    reported_.reserve(profile_.capacity());
  }

  Progress& progress() { return progress_; }

  // The input that messages are about from now on.
  void start_input(const std::string& input) {
    input_ = input;
    input_failures_ = 0;
  }

  int width() const { return width_; }
  int height() const { return height_; }

  // Frames after this are not a continuation of the frames before (another video, log or
  // folder): detectors that use earlier frames start afresh, and so does the laser pattern.
  void start_sequence() {
    detector_->reset(width_, height_);
    position_ = 0;
  }

  // One frame, as read (8 or 16 bit; 1 to 4 channels). `where` names it in messages and in the
  // CSV; `recorded_laser_on` is its laser state where the input records one (else
  // --laser-pattern says); `utime` is its exposure time (microseconds since the epoch) where the
  // input has one.
  void frame(const cv::Mat& raw, const std::string& where,
             std::optional<bool> recorded_laser_on = std::nullopt,
             std::optional<std::int64_t> utime = std::nullopt) {
    const std::int64_t index = next_frame_++;
    const bool laser_on = recorded_laser_on ? *recorded_laser_on : pattern_laser_on();
    ++position_;
    std::string problem;
    if (!laserline::tools::to_laser_mono8(raw, options_.channel, mono_, problem)) {
      fail(where + ": " + problem + "; skipped");
      return;
    }
    if (mono_.cols != width_ || mono_.rows != height_) {
      fail(where + ": image is " + std::to_string(mono_.cols) + "x" + std::to_string(mono_.rows) +
           " but the calibration " + options_.calib + " is for " + std::to_string(width_) + "x" +
           std::to_string(height_) + "; skipped");
      return;
    }
    const laserline::pipeline::ImageView view{mono_.data, mono_.cols, mono_.rows,
                                              static_cast<int>(mono_.step[0])};
    // Laser-off frames too: a detector that subtracts backgrounds keeps them as the next one's.
    detector_->detect(view, {static_cast<std::uint64_t>(index), laser_on}, profile_);
    if (profile_.overflowed()) ++overflowed_frames_;
    select_reported_points(laser_on);
    if (csv_ != nullptr) write_csv_points(index, where);
    if (ply_ != nullptr) add_to_cloud(index, where, utime);
    ++processed_;
    if (!laser_on) ++(recorded_laser_on ? laser_off_recorded_ : laser_off_by_pattern_);
    if (!options_.overlay_dir.empty()) write_overlay(index, where);
  }

  // A frame that could not be read at all: it keeps its frame number and its place in the
  // laser pattern.
  void unreadable_frame(const std::string& message) {
    ++next_frame_;
    ++position_;
    fail(message);
  }

  // A problem with an input as a whole (or an overlay): reported, counted, processing goes on.
  // A long video or log with a problem in every frame must not bury the rest: after
  // kShownPerInput lines for one input the others are only counted.
  void fail(const std::string& message) {
    ++failures_;
    ++input_failures_;
    if (input_failures_ <= kShownPerInput) progress_.message("laserline-extract: " + message);
    if (input_failures_ == kShownPerInput + 1) {
      progress_.message("laserline-extract: " + input_ +
                        ": further problems in this input are counted, not shown");
    }
  }

  std::int64_t frames() const { return next_frame_; }
  std::int64_t processed() const { return processed_; }
  std::int64_t laser_off_recorded() const { return laser_off_recorded_; }
  std::int64_t laser_off_by_pattern() const { return laser_off_by_pattern_; }
  std::int64_t failures() const { return failures_; }
  std::int64_t points_written() const { return points_written_; }
  std::int64_t valid_written() const { return valid_written_; }
  std::int64_t accepted() const { return accepted_; }
  // Accepted points of frames that had a pose (or of all frames, without --poses), and how many
  // of them were triangulated into the cloud.
  std::int64_t cloud_accepted() const { return cloud_accepted_; }
  std::int64_t cloud_triangulated() const { return cloud_triangulated_; }
  std::int64_t overflowed_frames() const { return overflowed_frames_; }

 private:
  bool pattern_laser_on() const {
    const auto& pattern = options_.laser_on_pattern;
    return pattern.empty() || pattern[static_cast<std::size_t>(position_) % pattern.size()];
  }

  // The points every output takes from this frame: none with the laser off (whatever a detector
  // makes of such a frame is not the laser); those in the region; rejected ones only when asked.
  void select_reported_points(bool laser_on) {
    reported_.clear();
    if (!laser_on) return;
    for (const auto& p : profile_.points()) {
      if (!p.valid && !options_.all_candidates) continue;
      if (!region_.contains(image_position(profile_, p))) continue;
      reported_.push_back(p);
      accepted_ += p.valid ? 1 : 0;
    }
  }

  // Every CSV row is written here (one place to add columns).
  void write_csv_points(std::int64_t index, const std::string& where) {
    const std::string source = csv_field(where);
    for (const auto& p : reported_) {
      const cv::Point2d at = image_position(profile_, p);
      std::fprintf(csv_, "%lld,%s,%d,%.4f,%.4f,%.4f,%.2f,%d,%d\n", static_cast<long long>(index),
                   source.c_str(), p.u, p.v, at.x, at.y, p.snr_db, p.segment, p.valid ? 1 : 0);
      ++points_written_;
      valid_written_ += p.valid ? 1 : 0;
    }
    if (std::fflush(csv_) != 0 || std::ferror(csv_) != 0) {
      progress_.message("laserline-extract: " + options_.output +
                        ": write failed: " + std::strerror(errno));
      throw laserline::cli::Exit(1);
    }
  }

  // The frame's triangulated points into the point cloud, moved into the world frame when there
  // are poses. A frame without a pose is reported and left out of the cloud (not of the CSV).
  void add_to_cloud(std::int64_t index, const std::string& where,
                    std::optional<std::int64_t> utime) {
    laserline::tools::Pose pose;
    if (poses_ != nullptr) {
      if (utime) {
        const double t = static_cast<double>(*utime) * 1e-6;
        if (!poses_->at_time(t, pose)) {
          char span[160];
          std::snprintf(span, sizeof span,
                        "at t=%.6f s is outside the pose log's time span %.6f .. %.6f s", t,
                        poses_->first_time(), poses_->last_time());
          fail(poses_->path() + ": frame " + std::to_string(index) + " (" + where + ") " + span +
               "; left out of " + options_.ply);
          return;
        }
      } else if (!poses_->at_index(static_cast<std::size_t>(index), pose)) {
        fail(poses_->path() + ": frame " + std::to_string(index) + " (" + where +
             ", no timestamp) has no pose: the log has " + std::to_string(poses_->size()) +
             " rows (frames without a time take the row of their frame number); left out of " +
             options_.ply);
        return;
      }
    }
    for (const auto& p : reported_) {
      if (!p.valid) continue;
      ++cloud_accepted_;
      // No 3-D point: the ray misses the laser sheet in front of the camera.
      if (!std::isfinite(p.xyz[2])) continue;
      const std::array<double, 3> camera{p.xyz[0], p.xyz[1], p.xyz[2]};
      ply_->add(poses_ != nullptr ? pose.apply(camera) : camera, p.snr_db);
      ++cloud_triangulated_;
    }
    if (!ply_->commit()) {
      progress_.message("laserline-extract: " + options_.ply +
                        ": write failed: " + std::strerror(errno));
      throw laserline::cli::Exit(1);
    }
  }

  void write_overlay(std::int64_t index, const std::string& where) {
    cv::cvtColor(mono_, overlay_, cv::COLOR_GRAY2BGR);
    constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
    for (const auto& p : reported_) {
      const cv::Point2d at = image_position(profile_, p);
      if (!std::isfinite(at.x) || !std::isfinite(at.y)) continue;
      const cv::Point centre(static_cast<int>(std::lround(at.x * 16.0)),
                             static_cast<int>(std::lround(at.y * 16.0)));
      const cv::Scalar colour = p.valid ? cv::Scalar(0, 255, 0) : cv::Scalar(0, 0, 255);
      // Half a pixel: the point marks the centre and leaves the line's flanks visible.
      cv::circle(overlay_, centre, 1 << (kShift - 1), colour, cv::FILLED, cv::LINE_AA, kShift);
    }
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06lld.png", static_cast<long long>(index));
    const std::string path = (fs::path(options_.overlay_dir) / name).string();
    bool written = false;
    try {
      written = cv::imwrite(path, overlay_);
    } catch (const cv::Exception&) {
      written = false;
    }
    if (!written) fail(path + ": overlay of " + where + " could not be written");
  }

  const Options& options_;
  int width_, height_;
  std::unique_ptr<laserline::pipeline::Detector> detector_;
  laserline::pipeline::Profile profile_;
  std::vector<laserline::pipeline::ProfilePoint> reported_;  // this frame's points in the outputs
  Region region_;
  FILE* csv_;
  laserline::tools::PlyWriter* ply_;
  const laserline::tools::PoseLog* poses_;
  Progress progress_;
  cv::Mat mono_, overlay_;
  std::int64_t next_frame_ = 0, processed_ = 0, failures_ = 0;
  std::int64_t position_ = 0;  // frames since the sequence started (the laser pattern's place)
  std::int64_t laser_off_recorded_ = 0, laser_off_by_pattern_ = 0;
  std::int64_t points_written_ = 0, valid_written_ = 0, accepted_ = 0;
  std::int64_t cloud_accepted_ = 0, cloud_triangulated_ = 0, overflowed_frames_ = 0;
  static constexpr int kShownPerInput = 10;
  std::string input_;
  int input_failures_ = 0;
};

// An image file: one frame, counted even when it cannot be read so that frame numbers follow
// the list of files. A damaged file (cut short, a failed CRC) is skipped whole: its decoder fills
// what is missing, and lines through the filled part would be false points.
void extract_image(Extractor& x, const std::string& path) {
  cv::Mat image;
  std::string problem;
  if (!laserline::tools::read_image_file(path, image, problem)) {
    x.unreadable_frame(path + ": " + problem + "; skipped");
    return;
  }
  x.frame(image, path);
}

void extract_video(Extractor& x, const std::string& path, std::size_t input, std::size_t inputs) {
  cv::VideoCapture video;
  try {
    video.open(path, cv::CAP_FFMPEG);
  } catch (const cv::Exception&) {
  }
  if (!video.isOpened()) {
    x.fail(path + ": not a readable video; skipped");
    return;
  }
  // Checked once here rather than once per frame.
  const int width = static_cast<int>(video.get(cv::CAP_PROP_FRAME_WIDTH));
  const int height = static_cast<int>(video.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (width > 0 && height > 0 && (width != x.width() || height != x.height())) {
    x.fail(path + ": video is " + std::to_string(width) + "x" + std::to_string(height) +
           " but the calibration is for " + std::to_string(x.width()) + "x" +
           std::to_string(x.height()) + "; skipped");
    return;
  }
  const double count = video.get(cv::CAP_PROP_FRAME_COUNT);
  cv::Mat frame;
  std::int64_t n = 0;
  const std::string name = fs::path(path).filename().string();
  while (true) {
    bool got = false;
    try {
      got = video.read(frame);
    } catch (const cv::Exception&) {
      got = false;
    }
    if (!got) break;
    x.frame(frame, path + " frame " + std::to_string(n));
    ++n;
    x.progress().update(input, inputs, name, count > 0 ? static_cast<double>(n) / count : 0.0,
                        x.frames());
  }
  if (n == 0) {
    x.fail(path + ": no frame could be decoded");
  } else if (count > 0 && static_cast<double>(n) < count) {
    // The container's own count (its header or index) against what decoded: a file cut short or
    // a decode that failed midway ends the frames early without an error from OpenCV.
    char announced[32];
    std::snprintf(announced, sizeof announced, "%.0f", count);
    x.fail(path + ": only " + std::to_string(n) + " of the " + announced +
           " frames its container announces could be decoded (cut short or damaged?); those " +
           std::to_string(n) + " were processed");
  }
}

// The calibration the frames are extracted with, and what a log must name to be extracted.
struct CalibrationInUse {
  std::uint64_t id = 0;
  std::string name;            // for messages: the file, or the log it came from
  bool accept_others = false;  // --override-log-calibration
};

std::string id_text(std::int64_t id) {
  return laserline::hal::calibration_id_text(static_cast<std::uint64_t>(id));
}

// What a log says of its calibration before its frames: its first laserline.calibration_t (the
// daemon publishes one at start, before any profile, and every few seconds), and the
// calibration_id of the first profile when that comes first (a logger started after the daemon).
// Reading stops at the first calibration_t: only a log without one is read to its end.
struct LogCalibration {
  std::optional<laserline::hal::Calibration> calibration;
  std::uint64_t id = 0;
  std::string where;  // the event that named the id; empty: the log names none
};

LogCalibration first_log_calibration(const std::string& path) {
  using laserline::messages::LcmLogReader;
  LogCalibration found;
  LcmLogReader log;
  std::string problem;
  if (!log.open(path, &problem)) return found;  // reported when the log is extracted
  const laserline::messages::Limits limits;
  LcmLogReader::Event event;
  LcmLogReader::Damage damage;
  laserline::calibration_t message;
  laserline::profile_t profile;
  laserline::hal::Calibration calibration;
  while (log.next(&event, &damage)) {
    const std::int64_t hash =
        laserline::messages::message_hash(event.data.data(), event.data.size());
    const std::string where =
        path + " event " + std::to_string(event.number) + " (" + event.channel + ")";
    if (hash == laserline::calibration_t::getHash() &&
        laserline::messages::decode(event.data.data(), event.data.size(), &message, limits,
                                    &problem) &&
        laserline::daemon::calibration_from_message(message, &calibration, &problem)) {
      const auto id = static_cast<std::uint64_t>(message.calibration_id);
      if (found.where.empty()) {
        found.id = id;
        found.where = where;
      }
      if (found.id == id) found.calibration = calibration;
      return found;
    }
    if (found.where.empty() && hash == laserline::profile_t::getHash() &&
        laserline::messages::decode(event.data.data(), event.data.size(), &profile, limits,
                                    &problem)) {
      found.id = static_cast<std::uint64_t>(profile.calibration_id);
      found.where = where;
    }
  }
  return found;
}

// An LCM log: every laserline.image_t message (on any channel) is a frame, in log order. The
// laser state of a frame comes from the profile_t of the same sequence number in the same log
// (image_t does not carry it); without one, from --laser-pattern (else on). Damaged records are
// skipped (reported with their byte offsets) and reading goes on at the next whole event; every
// message is decoded only after its lengths are checked (messages::decode). A log whose
// calibration_t or profiles name another calibration than the one in use is skipped whole.
void extract_log(Extractor& x, const std::string& path, std::size_t input, std::size_t inputs,
                 const CalibrationInUse& in_use) {
  using laserline::messages::LcmLogReader;
  const laserline::messages::Limits limits;
  std::map<std::int64_t, bool> laser_on_by_sequence;
  std::int64_t images = 0;
  LcmLogReader::Event event;
  LcmLogReader::Damage damage;
  std::string problem;
  {
    LcmLogReader log;
    if (!log.open(path, &problem)) {
      x.fail(problem + "; skipped");
      return;
    }
    laserline::profile_t profile;
    laserline::calibration_t calibration;
    std::string other_calibration;  // the first event naming another calibration
    while (log.next(&event, &damage)) {
      const std::int64_t hash =
          laserline::messages::message_hash(event.data.data(), event.data.size());
      std::optional<std::int64_t> named;
      if (hash == laserline::image_t::getHash()) {
        ++images;
      } else if (hash == laserline::profile_t::getHash() &&
                 laserline::messages::decode(event.data.data(), event.data.size(), &profile, limits,
                                             &problem)) {
        laser_on_by_sequence[profile.sequence] = profile.laser_on;
        named = profile.calibration_id;
      } else if (hash == laserline::calibration_t::getHash()) {
        if (laserline::messages::decode(event.data.data(), event.data.size(), &calibration, limits,
                                        &problem)) {
          named = calibration.calibration_id;
        } else {
          x.fail(path + " event " + std::to_string(event.number) + " (" + event.channel +
                 "): not a valid laserline.calibration_t: " + problem + "; skipped");
        }
      }
      if (named && static_cast<std::uint64_t>(*named) != in_use.id && other_calibration.empty()) {
        other_calibration = "event " + std::to_string(event.number) + " (" + event.channel +
                            ") names calibration " + id_text(*named);
      }
    }
    if (!other_calibration.empty() && !in_use.accept_others) {
      x.fail(path + ": " + other_calibration + ", not " +
             laserline::hal::calibration_id_text(in_use.id) + " of " + in_use.name +
             " in use; skipped (--override-log-calibration extracts it all the same)");
      return;
    }
  }
  if (images == 0) {
    x.fail(path + ": the LCM log holds no laserline.image_t message");
    return;
  }
  LcmLogReader log;
  if (!log.open(path, &problem)) {
    x.fail(problem + "; skipped");
    return;
  }
  const std::string name = fs::path(path).filename().string();
  std::int64_t n = 0;
  laserline::image_t message;
  cv::Mat image;
  while (true) {
    const bool more = log.next(&event, &damage);
    if (damage.bytes > 0) {
      const std::string range = "bytes " + std::to_string(damage.offset) + ".." +
                                std::to_string(damage.offset + damage.bytes - 1);
      x.fail(path + ": " + range +
             (more ? " are damaged (" + std::to_string(damage.records) +
                         " records); skipped, reading resumes at event " +
                         std::to_string(event.number)
                   : " are not a complete event (recording cut short?); ignored"));
    }
    if (!more) break;
    if (laserline::messages::message_hash(event.data.data(), event.data.size()) !=
        laserline::image_t::getHash()) {
      continue;
    }
    const std::string where =
        path + " event " + std::to_string(event.number) + " (" + event.channel + ")";
    ++n;
    if (!laserline::messages::decode(event.data.data(), event.data.size(), &message, limits,
                                     &problem)) {
      x.unreadable_frame(where + ": not a valid laserline.image_t: " + problem + "; skipped");
    } else if (!laserline::messages::unpack_image(message, limits, cv::IMREAD_UNCHANGED, &image,
                                                  &problem)) {
      x.unreadable_frame(where + ": " + problem + "; skipped");
    } else {
      const auto state = laser_on_by_sequence.find(message.sequence);
      x.frame(
          image, where,
          state != laser_on_by_sequence.end() ? std::optional<bool>(state->second) : std::nullopt,
          message.utime);
    }
    x.progress().update(input, inputs, name, static_cast<double>(n) / static_cast<double>(images),
                        x.frames());
  }
  if (log.totals().damaged_regions > 0) {
    x.fail(path + ": " + log.damage_summary());
  }
}

[[noreturn]] void usage_error(const std::string& line) {
  laserline::cli::usage_error("laserline-extract", line);
}

[[noreturn]] void fatal(const std::string& line) {
  std::fprintf(stderr, "laserline-extract: %s\n", line.c_str());
  throw laserline::cli::Exit(2);
}

std::string detector_list() {
  std::string list;
  for (const auto& name : laserline::pipeline::detector_names())
    list += (list.empty() ? "" : ", ") + name;
  return list;
}

Options parse_arguments(int argc, char** argv) {
  Options o;
  laserline::cli::Arguments args(argc, argv, "laserline-extract",
                                 std::string(kUsage) + "detectors: " + detector_list() + "\n",
                                 {{"calib", true},
                                  {"config", true},
                                  {"detector", true},
                                  {"threshold", true},
                                  {"channel", true},
                                  {"roi", true},
                                  {"mask", true},
                                  {"laser-pattern", true},
                                  {"overlay-dir", true},
                                  {"output", true},
                                  {"ply", true},
                                  {"poses", true},
                                  {"all-candidates", false},
                                  {"override-log-calibration", false}});
  while (args.next()) {
    const std::string& arg = args.name();
    if (arg.empty()) {
      o.inputs.push_back(args.value());
      continue;
    }
    auto value = [&]() -> std::string { return args.value(); };
    if (arg == "--calib") {
      o.calib = value();
    } else if (arg == "--config") {
      o.config = value();
    } else if (arg == "--detector") {
      o.detector = value();
    } else if (arg == "--threshold") {
      o.threshold = value();
    } else if (arg == "--channel") {
      try {
        o.channel = laserline::hal::parse_laser_channel(value());
      } catch (const std::invalid_argument& e) {
        fatal(std::string("--") + e.what());  // the reason starts: channel "TEXT": ...
      }
    } else if (arg == "--roi") {
      o.roi = value();
    } else if (arg == "--mask") {
      o.mask = value();
    } else if (arg == "--laser-pattern") {
      o.laser_pattern = value();
      const std::string& bits = o.laser_pattern;
      if (bits.empty() || bits.size() > 1024 || bits.find_first_not_of("01") != std::string::npos) {
        fatal("--laser-pattern '" + bits +
              "': expected 1 to 1024 characters 0 (laser off) or 1 (laser on), e.g. 10 for "
              "on/off alternation");
      }
      if (bits.find('1') == std::string::npos) {
        fatal("--laser-pattern '" + bits + "': has no 1, so no frame would have the laser on");
      }
      o.laser_on_pattern.clear();
      for (char bit : bits)
        o.laser_on_pattern.push_back(bit == '1');
    } else if (arg == "--overlay-dir") {
      o.overlay_dir = value();
    } else if (arg == "--output") {
      o.output = value();
    } else if (arg == "--ply") {
      o.ply = value();
    } else if (arg == "--poses") {
      o.poses = value();
    } else if (arg == "--all-candidates") {
      o.all_candidates = true;
    } else if (arg == "--override-log-calibration") {
      o.override_log_calibration = true;
    }
  }
  if (o.override_log_calibration && o.calib.empty()) {
    usage_error("--override-log-calibration goes with --calib");
  }
  if (o.detector.empty()) usage_error("--detector is required (one of: " + detector_list() + ")");
  if (o.output.empty() && o.ply.empty()) usage_error("--output or --ply is required");
  if (!o.poses.empty() && o.ply.empty()) usage_error("--poses needs --ply");
  if (o.inputs.empty()) usage_error("no INPUT given");
  return o;
}

// --threshold into the chosen detector's own option, in its own unit.
void apply_threshold(const Options& o, laserline::pipeline::DetectorOptions& detector_options) {
  if (o.threshold.empty()) return;
  const char* text = o.threshold.c_str();
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(text, &end);
  const bool number = errno == 0 && end != text && *end == '\0' && std::isfinite(value);
  if (o.detector == "maxvalue") {
    if (!number || value != std::floor(value) || value < 1 || value > 255) {
      fatal("--threshold " + o.threshold +
            ": the maxvalue detector's threshold is a grey level, a whole number from 1 to 255");
    }
    detector_options.maxvalue_threshold = static_cast<int>(value);
  } else {
    if (!number || value < 0 || value > 60) {
      fatal("--threshold " + o.threshold + ": the " + o.detector +
            " detector's threshold is an SNR in dB, a number from 0 to 60");
    }
    detector_options.frontend.snr_threshold_db = value;
  }
}

// --roi and --mask, checked against the frames' size (the calibration's).
Region region_of(const Options& o, int width, int height) {
  Region region;
  const std::string frames = std::to_string(width) + "x" + std::to_string(height) +
                             " frames of the calibration " + o.calib;
  if (!o.roi.empty()) {
    int x = 0, y = 0, w = 0, h = 0;
    char tail = 0;
    if (std::sscanf(o.roi.c_str(), "%d,%d,%d,%d%c", &x, &y, &w, &h, &tail) != 4 || x < 0 || y < 0 ||
        w < 1 || h < 1) {
      fatal("--roi '" + o.roi +
            "': expected x,y,w,h: left column, top row (from 0), width and height (from 1) in "
            "pixels, e.g. 0,100,1280,600");
    }
    if (static_cast<long>(x) + w > width || static_cast<long>(y) + h > height) {
      fatal("--roi " + o.roi + ": reaches beyond the " + frames);
    }
    region.limit_to(cv::Rect(x, y, w, h));
  }
  if (!o.mask.empty()) {
    cv::Mat image;
    try {
      image = cv::imread(o.mask, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception&) {
      image.release();
    }
    if (image.empty()) {
      fatal("--mask " + o.mask + ": " +
            (access(o.mask.c_str(), R_OK) != 0
                 ? std::string("cannot be read: ") + std::strerror(errno)
                 : std::string("not a readable image")));
    }
    if (image.cols != width || image.rows != height) {
      fatal("--mask " + o.mask + ": is " + std::to_string(image.cols) + "x" +
            std::to_string(image.rows) + " but must have the size of the " + frames);
    }
    // Any colour channel set marks a kept pixel (an alpha channel does not count).
    std::vector<cv::Mat> planes;
    cv::split(image, planes);
    const std::size_t colours = planes.size() >= 3 ? 3 : 1;  // grey or BGR, each maybe + alpha
    cv::Mat kept = planes[0] != 0;
    for (std::size_t c = 1; c < colours; ++c)
      kept |= planes[c] != 0;
    if (cv::countNonZero(kept) == 0) {
      fatal("--mask " + o.mask + ": no pixel is set (points are kept on non-zero pixels)");
    }
    region.limit_to(kept);
  }
  return region;
}

enum class InputKind : std::uint8_t { kMissing, kFolder, kLog, kVideo, kImage };

InputKind kind_of(const std::string& input) {
  std::error_code ec;
  if (!fs::exists(input, ec)) return InputKind::kMissing;
  if (fs::is_directory(input, ec)) return InputKind::kFolder;
  if (is_lcm_log(input)) return InputKind::kLog;
  if (has_extension(input, kVideoExtensions)) return InputKind::kVideo;
  return InputKind::kImage;
}

// Image arguments are taken in the order given. When a run of them is not in natural order
// (a shell glob sorts step_num10.png before step_num2.png), says so once, before it starts.
void note_unnatural_order(Extractor& x, const std::vector<std::string>& inputs,
                          const std::vector<InputKind>& kinds, std::size_t first) {
  std::size_t end = first;
  while (end < inputs.size() && kinds[end] == InputKind::kImage)
    ++end;
  for (std::size_t i = first + 1; i < end; ++i) {
    if (!laserline::tools::natural_less(inputs[i], inputs[i - 1])) continue;
    x.progress().message("laserline-extract: note: the " + std::to_string(end - first) +
                         " image arguments from " + inputs[first] +
                         " on are not in natural order (" +
                         fs::path(inputs[i - 1]).filename().string() + " before " +
                         fs::path(inputs[i]).filename().string() +
                         "): frames are numbered in the order given; give their folder to read "
                         "them in natural order");
    return;
  }
}

// The image files of a folder, in natural order (empty with `ec` set when it cannot be listed).
std::vector<std::string> images_in_folder(const std::string& folder, std::error_code& ec) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (entry.is_regular_file(ec) && has_extension(entry.path(), kImageExtensions)) {
      files.push_back(entry.path());
    }
  }
  if (ec) return {};
  std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
    return laserline::tools::natural_less(a.filename().string(), b.filename().string());
  });
  std::vector<std::string> names;
  for (const auto& f : files)
    names.push_back(f.string());
  return names;
}

int run_extract(int argc, char** argv) {
  // OpenCV's own warnings (e.g. a failing decoder) would duplicate our one line per problem.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  Options options = parse_arguments(argc, argv);

  const auto names = laserline::pipeline::detector_names();
  if (std::find(names.begin(), names.end(), options.detector) == names.end()) {
    fatal("--detector: unknown detector '" + options.detector + "' (one of: " + detector_list() +
          ")");
  }
  std::vector<InputKind> kinds;
  for (const auto& input : options.inputs)
    kinds.push_back(kind_of(input));
  laserline::hal::Calibration calibration;
  CalibrationInUse in_use;
  in_use.accept_others = options.override_log_calibration;
  if (!options.calib.empty()) {
    try {
      calibration = laserline::hal::load_calibration_file(options.calib);
    } catch (const ConfigError& e) {
      fatal(e.what());
    }
    in_use.id = laserline::hal::calibration_id(calibration);
    in_use.name = options.calib;
  }
  // What the logs among the inputs were recorded with: before any output is written.
  std::optional<LogCalibration> from_log;
  for (std::size_t i = 0; i < options.inputs.size(); ++i) {
    if (kinds[i] != InputKind::kLog) continue;
    LogCalibration log = first_log_calibration(options.inputs[i]);
    if (log.where.empty()) continue;
    if (!options.calib.empty()) {
      if (log.id != in_use.id && !options.override_log_calibration) {
        fatal("--calib " + options.calib + " is calibration " +
              laserline::hal::calibration_id_text(in_use.id) + ", but " + options.inputs[i] +
              " was recorded with calibration " + laserline::hal::calibration_id_text(log.id) +
              " (" + log.where +
              "); leave out --calib to use the log's, or add --override-log-calibration");
      }
    } else if (!from_log) {
      from_log = std::move(log);
    } else if (log.id != from_log->id) {
      fatal(options.inputs[i] + " was recorded with calibration " +
            laserline::hal::calibration_id_text(log.id) + " (" + log.where + "), " +
            from_log->where + " with calibration " +
            laserline::hal::calibration_id_text(from_log->id) +
            ": extract them apart, or give --calib");
    }
  }
  if (options.calib.empty()) {
    if (!from_log) {
      usage_error(
          "--calib is required: no input is an LCM log that carries a "
          "laserline.calibration_t");
    }
    if (!from_log->calibration) {
      usage_error("--calib is required: the profiles of " + from_log->where + " name calibration " +
                  laserline::hal::calibration_id_text(from_log->id) +
                  ", but no laserline.calibration_t in the log carries it");
    }
    calibration = *from_log->calibration;
    in_use.id = from_log->id;
    const std::string log_path = from_log->where.substr(0, from_log->where.find(" event "));
    in_use.name = log_path + "'s calibration_t";
    options.calib = in_use.name;  // names the calibration in messages
    std::fprintf(stderr, "laserline-extract: calibration %s from the log %s\n",
                 laserline::hal::calibration_id_text(in_use.id).c_str(), log_path.c_str());
  }
  laserline::pipeline::DetectorOptions detector_options;
  try {
    // The configuration's detector section (thresholds, front-end, motion); its calibration is
    // replaced by --calib.
    const laserline::daemon::DaemonConfig config =
        options.config.empty() ? laserline::daemon::builtin_config()
                               : laserline::daemon::load_config_file(options.config);
    detector_options = config.detector_options;
    detector_options.geometry = laserline::daemon::scanner_geometry(calibration);
    // Before any frame: a sheet the camera cannot see would give no point, or none in 3-D.
    laserline::daemon::check_laser_sheet_in_view(
        calibration, {options.calib, "laser"},
        laserline::daemon::searches_depth_range(options.detector) ? &detector_options.frontend
                                                                  : nullptr,
        config.source);
  } catch (const ConfigError& e) {
    fatal(e.what());
  }
  apply_threshold(options, detector_options);
  const Region region = region_of(options, calibration.camera.width, calibration.camera.height);
  std::unique_ptr<laserline::pipeline::Detector> detector;
  try {
    detector = laserline::pipeline::make_detector(options.detector, detector_options);
  } catch (const std::invalid_argument& e) {
    fatal("--detector " + options.detector + ": " + e.what());
  }
  if (!detector) fatal("--detector: unknown detector '" + options.detector + "'");

  if (!options.overlay_dir.empty()) {
    std::error_code ec;
    fs::create_directories(options.overlay_dir, ec);
    if (ec || !fs::is_directory(options.overlay_dir)) {
      fatal("--overlay-dir " + options.overlay_dir +
            ": cannot be created: " + (ec ? ec.message() : std::string("not a directory")));
    }
  }
  std::optional<laserline::tools::PoseLog> poses;
  std::optional<laserline::tools::PlyWriter> ply;
  try {
    if (!options.poses.empty()) poses = laserline::tools::PoseLog::load(options.poses);
    if (!options.ply.empty()) {
      ply.emplace(options.ply, poses ? "laserline-extract: metres, world frame of " + options.poses
                                     : std::string("laserline-extract: metres, camera frame"));
    }
  } catch (const laserline::tools::PointCloudError& e) {
    fatal(e.what());
  }
  FILE* csv = nullptr;
  if (!options.output.empty()) {
    csv = std::fopen(options.output.c_str(), "w");
    if (csv == nullptr) {
      fatal("--output " + options.output + ": cannot be written: " + std::strerror(errno));
    }
    std::fputs("frame,source,u,v,x,y,snr_db,segment,valid\n", csv);
    std::fflush(csv);
  }

  Extractor x(options, calibration, std::move(detector), region, csv, ply ? &*ply : nullptr,
              poses ? &*poses : nullptr);
  for (std::size_t i = 0; i < options.inputs.size(); ++i) {
    const std::string& input = options.inputs[i];
    const std::size_t number = i + 1, inputs = options.inputs.size();
    const std::string name = fs::path(input).filename().string();
    x.start_input(input);
    switch (kinds[i]) {
      case InputKind::kMissing:
        // Not known to be a frame at all: takes no frame number.
        x.fail(input + ": no such file or folder; skipped");
        break;
      case InputKind::kFolder: {
        std::error_code ec;
        const std::vector<std::string> files = images_in_folder(input, ec);
        if (ec) {
          x.fail(input + ": folder cannot be listed: " + ec.message() + "; skipped");
          break;
        }
        if (files.empty()) {
          x.fail(input + ": folder holds no image file; skipped");
          break;
        }
        x.start_sequence();
        for (std::size_t k = 0; k < files.size(); ++k) {
          extract_image(x, files[k]);
          x.progress().update(number, inputs, name,
                              static_cast<double>(k + 1) / static_cast<double>(files.size()),
                              x.frames());
        }
        break;
      }
      case InputKind::kLog:
        x.start_sequence();
        extract_log(x, input, number, inputs, in_use);
        break;
      case InputKind::kVideo:
        x.start_sequence();
        extract_video(x, input, number, inputs);
        break;
      case InputKind::kImage:
        // Consecutive image arguments are one sequence (a shell glob).
        if (i == 0 || kinds[i - 1] != InputKind::kImage) {
          x.start_sequence();
          note_unnatural_order(x, options.inputs, kinds, i);
        }
        extract_image(x, input);
        x.progress().update(number, inputs, name, 1.0, x.frames());
        break;
    }
  }
  x.progress().clear();
  if (csv != nullptr) std::fclose(csv);
  const std::string problems =
      x.failures() > 0 ? ", " + std::to_string(x.failures()) + " problems (see above)" : "";
  std::string written;
  if (csv != nullptr) {
    written = ", " + std::to_string(x.points_written()) + " points written (" +
              std::to_string(x.valid_written()) + " valid) to " + options.output;
  }
  std::fprintf(stderr,
               "laserline-extract: %lld frames from %zu inputs, %lld processed with %s%s%s\n",
               static_cast<long long>(x.frames()), options.inputs.size(),
               static_cast<long long>(x.processed()), options.detector.c_str(), written.c_str(),
               problems.c_str());
  if (ply) {
    std::fprintf(stderr, "laserline-extract: %lld 3-D points in %s (%s)\n",
                 static_cast<long long>(ply->count()), options.ply.c_str(),
                 poses ? ("world frame of " + options.poses).c_str() : "camera frame");
  }
  const std::int64_t laser_off = x.laser_off_recorded() + x.laser_off_by_pattern();
  if (laser_off > 0) {
    std::string from;
    if (x.laser_off_recorded() > 0) {
      from = std::to_string(x.laser_off_recorded()) + " from the log's profiles";
    }
    if (x.laser_off_by_pattern() > 0) {
      from += (from.empty() ? "" : ", ") + std::to_string(x.laser_off_by_pattern()) +
              " from --laser-pattern " + options.laser_pattern;
    }
    std::fprintf(stderr,
                 "laserline-extract: %lld of the processed frames were exposed with the laser off "
                 "(%s): no points taken from them\n",
                 static_cast<long long>(laser_off), from.c_str());
  }
  if (x.overflowed_frames() > 0) {
    std::fprintf(stderr, "laserline-extract: %lld frames had more points than the detector keeps\n",
                 static_cast<long long>(x.overflowed_frames()));
  }
  // A run that read frames but has nothing to show for them is not a success.
  bool empty_result = false;
  if (x.processed() > 0 && x.accepted() == 0) {
    std::fprintf(stderr,
                 "laserline-extract: no point accepted in any of the %lld processed frames (see "
                 "--channel, --threshold, --roi, --mask, --laser-pattern, --detector)\n",
                 static_cast<long long>(x.processed()));
    empty_result = true;
  }
  const std::int64_t dropped = x.cloud_accepted() - x.cloud_triangulated();
  if (ply && dropped * 2 > x.cloud_accepted()) {
    std::fprintf(stderr,
                 "laserline-extract: %lld of %lld accepted points (%.1f%%) have no 3-D point and "
                 "are left out of %s: their rays do not meet the laser sheet of %s in front of "
                 "the camera (is its plane's sign or the laser's side wrong?)\n",
                 static_cast<long long>(dropped), static_cast<long long>(x.cloud_accepted()),
                 100.0 * static_cast<double>(dropped) / static_cast<double>(x.cloud_accepted()),
                 options.ply.c_str(), options.calib.c_str());
    empty_result = true;
  }
  if (empty_result) return 3;
  return x.failures() > 0 ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_extract);
}
