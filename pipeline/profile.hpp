#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "pipeline/search_axes.hpp"

namespace laserline::pipeline {

// One laser point in the detector's search coordinates (Profile::axes()): for the paper's mounting
// u is the column and v the row of the original frame (pixel centres at integers).
struct ProfilePoint {
  int u = 0;            // the epipolar line it lies on (a column, a row, or a line at an angle)
  float v = 0.0f;       // sub-pixel position along that line (a row, a column, ...)
  float snr_db = 0.0f;  // 20*log10 of the detector's signal-to-noise amplitude ratio
  std::int32_t segment = -1;
  bool valid = true;
  std::array<float, 3> xyz{std::numeric_limits<float>::quiet_NaN(),
                           std::numeric_limits<float>::quiet_NaN(),
                           std::numeric_limits<float>::quiet_NaN()};
};

// The points of one frame. Its capacity is fixed at construction so that filling it on the frame
// path never allocates; a detector that finds more points than fit stops adding and the profile
// says it overflowed. It says how its points map to the image (axes()).
class Profile {
 public:
  explicit Profile(std::size_t capacity = 0) { points_.reserve(capacity); }
  // Copies keep the capacity (std::vector's copy would not): ring slots are made by copying a
  // prototype and must be able to hold a full frame's points without allocating.
  Profile(const Profile& other)
      : axes_(other.axes_),
        background_sequence_(other.background_sequence_),
        background_laser_off_(other.background_laser_off_),
        background_line_removed_(other.background_line_removed_),
        overflowed_(other.overflowed_) {
    points_.reserve(other.capacity());
    points_ = other.points_;
  }
  Profile& operator=(const Profile& other) {
    if (this != &other) {
      if (points_.capacity() < other.capacity()) points_.reserve(other.capacity());
      points_.assign(other.points_.begin(), other.points_.end());
      axes_ = other.axes_;
      background_sequence_ = other.background_sequence_;
      background_laser_off_ = other.background_laser_off_;
      background_line_removed_ = other.background_line_removed_;
      overflowed_ = other.overflowed_;
    }
    return *this;
  }
  Profile(Profile&&) noexcept = default;
  Profile& operator=(Profile&&) noexcept = default;

  void clear() {
    points_.clear();
    overflowed_ = false;
    background_sequence_ = -1;
    background_laser_off_ = false;
    background_line_removed_ = false;
  }
  // Adds a point unless full; returns false (and marks the overflow) when full.
  bool add(const ProfilePoint& point) {
    if (points_.size() == points_.capacity()) {
      overflowed_ = true;
      return false;
    }
    points_.push_back(point);
    return true;
  }

  // Keeps the points for which keep(point) holds, in order (no allocation).
  template <class Predicate>
  void keep_if(Predicate keep) {
    std::size_t kept = 0;
    for (const ProfilePoint& p : points_) {
      if (keep(p)) points_[kept++] = p;
    }
    points_.resize(kept);
  }

  const std::vector<ProfilePoint>& points() const { return points_; }
  // The points for a later stage to complete in place (e.g. xyz); their number stays fixed.
  std::span<ProfilePoint> mutable_points() { return points_; }
  std::size_t size() const { return points_.size(); }
  std::size_t capacity() const { return points_.capacity(); }
  bool overflowed() const { return overflowed_; }

  // The frame subtracted as the background (paper III-A): its sequence number, -1 for none (the
  // frame was searched as it is), whether it was exposed with the laser off, and whether its own
  // laser line was taken out of it first (the scene had not moved away from that line).
  std::int64_t background_sequence() const { return background_sequence_; }
  bool background_laser_off() const { return background_laser_off_; }
  bool background_line_removed() const { return background_line_removed_; }
  void set_background(std::int64_t sequence, bool laser_off, bool line_removed = false) {
    background_sequence_ = sequence;
    background_laser_off_ = laser_off;
    background_line_removed_ = line_removed;
  }

  // How (u, v) of the points map to the frame's pixels; set by the detector.
  const SearchAxes& axes() const { return axes_; }
  void set_axes(const SearchAxes& axes) { axes_ = axes; }
  // A point in the frame's pixel coordinates (x right, y down).
  std::array<double, 2> image_point(const ProfilePoint& p) const {
    return axes_.to_image(p.u, p.v);
  }

 private:
  std::vector<ProfilePoint> points_;
  SearchAxes axes_;
  std::int64_t background_sequence_ = -1;
  bool background_laser_off_ = false;
  bool background_line_removed_ = false;
  bool overflowed_ = false;
};

}  // namespace laserline::pipeline
