// laserline-extract's work on each frame: the detector, then the points into every output asked
// for (the CSV, the point cloud, the overlays), what failed reported and counted. Single-threaded.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/laser_channel.hpp"
#include "pipeline/detector.hpp"
#include "tools/line_width.hpp"
#include "tools/point_cloud.hpp"

namespace laserline::tools::extract {

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
    if (silent_) return;
    clear();
    std::fprintf(stderr, "%s\n", line.c_str());
  }
  // Neither progress nor messages (a pass whose frames are read again).
  void silence() {
    enabled_ = false;
    silent_ = true;
  }
  void clear() {
    if (shown_) std::fputs("\r\033[K", stderr);
    shown_ = false;
  }

 private:
  bool enabled_;
  bool silent_ = false;
  bool shown_ = false;
  std::chrono::steady_clock::time_point last_{};
};

struct Options {
  bool override_log_calibration = false;
  std::string calib, config, detector, overlay_dir, output, ply, poses;
  // As given; checked once the calibration and the detector are known.
  std::string threshold, roi, mask, depth_range;
  laserline::hal::LaserChannel channel;  // the laser's light in colour frames
  int clipped_from = 255;     // colours at this level or above are clipped (the detector's)
  int bit_depth = 0;          // 16-bit frames' sample bits (--bit-depth); 0: from the frames
  std::string laser_pattern;  // as given, for messages
  std::vector<bool> laser_on_pattern;  // empty: every frame the input says nothing of is "on"
  bool all_candidates = false;
  bool keep_sheet_width = false;  // the filters sized for the calibration's sheet width
  std::vector<std::string> inputs;
};

// --output as messages name it: "-" is standard output.
inline std::string output_name(const Options& o) {
  return o.output == "-" ? "standard output" : o.output;
}

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

// Runs the detector on frames and writes what it finds; counts what failed.
class Extractor {
 public:
  // csv, ply and poses may be null (not asked for).
  Extractor(const Options& options, const laserline::hal::Calibration& calibration,
            std::unique_ptr<laserline::pipeline::Detector> detector, const Region& region,
            FILE* csv, laserline::tools::PlyWriter* ply, const laserline::tools::PoseLog* poses);

  Progress& progress() { return progress_; }
  // Instead of writing anything, measures the laser line's width on the first `frames` frames
  // (their laser-on ones) into `meter`, silently: the pass that writes reports the problems.
  void measure_width_only(laserline::tools::LineWidthMeter& meter, std::int64_t frames) {
    width_meter_ = &meter;
    frame_limit_ = frames;
    progress_.silence();
  }
  // How much laser line a frame shows: the sum over its valid points of their SNR above the
  // detector's threshold (dB), and where it stands: its sequence (counted from 0) and its place
  // in it (the laser pattern's place).
  struct FrameEvidence {
    std::int64_t sequence = 0, position = 0;
    double evidence = 0;
  };
  // Instead of writing anything, records the evidence of the first `frames` frames, each taken as
  // laser-on, into `out`, silently.
  void measure_evidence_only(std::vector<FrameEvidence>& out, std::int64_t frames,
                             double threshold_db) {
    evidence_ = &out;
    evidence_threshold_db_ = threshold_db;
    frame_limit_ = frames;
    progress_.silence();
  }
  // No more frames wanted (the measuring pass has its frames).
  bool done() const {
    return (width_meter_ != nullptr || evidence_ != nullptr) && next_frame_ >= frame_limit_;
  }

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
    sample_bits_ = 0;
    ++sequence_;
  }

  // One frame, as read (8 or 16 bit; 1 to 4 channels). `where` names it in messages and in the
  // CSV; `recorded_laser_on` is its laser state where the input records one (else
  // --laser-pattern says); `utime` is its exposure time (microseconds since the epoch) where the
  // input has one.
  void frame(const cv::Mat& raw, const std::string& where,
             std::optional<bool> recorded_laser_on = std::nullopt,
             std::optional<std::int64_t> utime = std::nullopt);

  // A frame that could not be read at all: it keeps its frame number and its place in the
  // laser pattern.
  void unreadable_frame(const std::string& message);

  // A problem with an input as a whole (or an overlay): reported, counted, processing goes on.
  // A long video or log with a problem in every frame must not bury the rest: after
  // kShownPerInput lines for one input the others are only counted.
  void fail(const std::string& message);

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
  bool pattern_laser_on() const;
  // The bits of a 16-bit frame's samples (--bit-depth, else chosen at the sequence's first 16-bit
  // frame and raised where a later one needs more, the detector then starting afresh: its
  // background would be in other units).
  int sample_bits(const cv::Mat& raw, const std::string& where);

  // The points every output takes from this frame: none with the laser off (whatever a detector
  // makes of such a frame is not the laser); those in the region; rejected ones only when asked.
  void select_reported_points(bool laser_on);

  // Every CSV row is written here (one place to add columns).
  void write_csv_points(std::int64_t index, const std::string& where);

  // The frame's triangulated points into the point cloud, moved into the world frame when there
  // are poses. A frame without a pose is reported and left out of the cloud (not of the CSV).
  void add_to_cloud(std::int64_t index, const std::string& where,
                    std::optional<std::int64_t> utime);
  void write_overlay(std::int64_t index, const std::string& where);

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
  std::int64_t sequence_ = -1;  // sequences started
  int sample_bits_ = 0;         // this sequence's 16-bit frames' (0: none yet)
  laserline::tools::LineWidthMeter* width_meter_ = nullptr;
  std::vector<FrameEvidence>* evidence_ = nullptr;
  double evidence_threshold_db_ = 0;
  std::int64_t frame_limit_ = 0;
  static constexpr int kShownPerInput = 10;
  std::string input_;
  int input_failures_ = 0;
};

}  // namespace laserline::tools::extract
