#include "tools/extractor.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tools/cli.hpp"
#include "tools/frame_channel.hpp"

namespace laserline::tools::extract {

namespace {

namespace fs = std::filesystem;

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

}  // namespace

Extractor::Extractor(const Options& options, const laserline::hal::Calibration& calibration,
                     std::unique_ptr<laserline::pipeline::Detector> detector, const Region& region,
                     FILE* csv, laserline::tools::PlyWriter* ply,
                     const laserline::tools::PoseLog* poses)
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

void Extractor::frame(const cv::Mat& raw, const std::string& where,
                      std::optional<bool> recorded_laser_on, std::optional<std::int64_t> utime) {
  const std::int64_t index = next_frame_++;
  const bool laser_on = recorded_laser_on ? *recorded_laser_on : pattern_laser_on();
  ++position_;
  std::string problem;
  if (!laserline::tools::to_laser_mono8(raw, options_.channel, options_.clipped_from,
                                        sample_bits(raw, where), mono_, problem)) {
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
  if (width_meter_ != nullptr) {
    if (laser_on) width_meter_->add(mono_, profile_);
    return;
  }
  if (evidence_ != nullptr) {
    double evidence = 0;
    for (const laserline::pipeline::ProfilePoint& p : profile_.points())
      if (p.valid)
        evidence += std::max(0.0, static_cast<double>(p.snr_db) - evidence_threshold_db_);
    evidence_->push_back({sequence_, position_ - 1, evidence});
    return;
  }
  if (profile_.overflowed()) ++overflowed_frames_;
  select_reported_points(laser_on);
  if (csv_ != nullptr) write_csv_points(index, where);
  if (ply_ != nullptr) add_to_cloud(index, where, utime);
  ++processed_;
  if (!laser_on) ++(recorded_laser_on ? laser_off_recorded_ : laser_off_by_pattern_);
  if (!options_.overlay_dir.empty()) write_overlay(index, where);
}

int Extractor::sample_bits(const cv::Mat& raw, const std::string& where) {
  if (raw.depth() != CV_16U) return 8;
  if (options_.bit_depth != 0) return options_.bit_depth;
  const int needed = laserline::tools::significant_bits(raw);
  if (sample_bits_ == 0) {
    sample_bits_ = needed;
    if (needed < 16) {
      progress_.message("laserline-extract: " + where + ": 16-bit samples of at most " +
                        std::to_string(needed) + " bits: read as " + std::to_string(needed) +
                        "-bit (--bit-depth N to say how many bits the camera gives)");
    }
  } else if (needed > sample_bits_) {
    progress_.message("laserline-extract: " + where + ": samples beyond the " +
                      std::to_string(sample_bits_) + " bits of the frames before: read as " +
                      std::to_string(needed) +
                      "-bit from here on, the detector starting afresh (--bit-depth N to fix it)");
    sample_bits_ = needed;
    detector_->reset(width_, height_);
  }
  return sample_bits_;
}

void Extractor::unreadable_frame(const std::string& message) {
  ++next_frame_;
  ++position_;
  fail(message);
}

void Extractor::fail(const std::string& message) {
  ++failures_;
  ++input_failures_;
  if (input_failures_ <= kShownPerInput) progress_.message("laserline-extract: " + message);
  if (input_failures_ == kShownPerInput + 1) {
    progress_.message("laserline-extract: " + input_ +
                      ": further problems in this input are counted, not shown");
  }
}

bool Extractor::pattern_laser_on() const {
  const auto& pattern = options_.laser_on_pattern;
  return pattern.empty() || pattern[static_cast<std::size_t>(position_) % pattern.size()];
}

void Extractor::select_reported_points(bool laser_on) {
  reported_.clear();
  if (!laser_on) return;
  for (const auto& p : profile_.points()) {
    if (!p.valid && !options_.all_candidates) continue;
    if (!region_.contains(image_position(profile_, p))) continue;
    reported_.push_back(p);
    accepted_ += p.valid ? 1 : 0;
  }
}

void Extractor::write_csv_points(std::int64_t index, const std::string& where) {
  const std::string source = csv_field(where);
  for (const auto& p : reported_) {
    const cv::Point2d at = image_position(profile_, p);
    std::fprintf(csv_, "%lld,%s,%d,%.4f,%.4f,%.4f,%.2f,%d,%d\n", static_cast<long long>(index),
                 source.c_str(), p.u, p.v, at.x, at.y, p.snr_db, p.segment, p.valid ? 1 : 0);
    ++points_written_;
    valid_written_ += p.valid ? 1 : 0;
  }
  if (std::fflush(csv_) != 0 || std::ferror(csv_) != 0) {
    progress_.message("laserline-extract: " + output_name(options_) +
                      ": write failed: " + std::strerror(errno));
    throw laserline::cli::Exit(1);
  }
}

void Extractor::add_to_cloud(std::int64_t index, const std::string& where,
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
    const Eigen::Vector3d camera(p.xyz[0], p.xyz[1], p.xyz[2]);
    ply_->add(poses_ != nullptr ? pose.apply(camera) : camera, p.snr_db);
    ++cloud_triangulated_;
  }
  if (!ply_->commit()) {
    progress_.message("laserline-extract: " + options_.ply +
                      ": write failed: " + std::strerror(errno));
    throw laserline::cli::Exit(1);
  }
}

void Extractor::write_overlay(std::int64_t index, const std::string& where) {
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

}  // namespace laserline::tools::extract
