#include "pipeline/detector.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "pipeline/backprojection_detector.hpp"
#include "pipeline/frontend_detectors.hpp"
#include "pipeline/maxvalue_detector.hpp"
#include "pipeline/options.hpp"
#include "pipeline/search_axes.hpp"
#include "pipeline/triangulation.hpp"

namespace laserline::pipeline {

namespace {

// Any detector run in search coordinates: each frame made into its search image (the frame
// itself, its transpose, or its rotation), the points kept within the frame and the profile told
// how they map to it.
class SearchAxesDetector final : public Detector {
 public:
  SearchAxesDetector(std::unique_ptr<Detector> detector, const SearchAxes& axes,
                     const ScannerGeometry& geometry)
      : detector_(std::move(detector)),
        axes_(axes),
        width_(geometry.width),
        height_(geometry.height) {}

  const char* name() const override { return detector_->name(); }
  std::size_t max_points(int width, int height) const override {
    return axes_.identity() ? detector_->max_points(width, height)
                            : detector_->max_points(axes_.lines, axes_.length);
  }
  void reset(int width, int height) override {
    if (axes_.identity()) {
      axes_.lines = width;
      axes_.length = height;
      detector_->reset(width, height);
    } else {
      // The search image is laid out for the calibrated frame size.
      if (width != width_ || height != height_) {
        throw std::invalid_argument("frame size " + std::to_string(width) + "x" +
                                    std::to_string(height) + " differs from the calibration's " +
                                    std::to_string(width_) + "x" + std::to_string(height_));
      }
      detector_->reset(axes_.lines, axes_.length);
    }
    search_.reset(axes_, width, height);
    frame_width_ = width;
    frame_height_ = height;
    set_region(region_);
  }
  void use_parts(PartRunner& runner) override { detector_->use_parts(runner); }
  void set_region(const DetectionRegion& region) override {
    region_ = region;
    detector_->set_region(search_region());
  }
  DetectionRegion region() const override { return region_.in_frame(frame_width_, frame_height_); }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override {
    detector_->detect(search_.make(image), frame, out);
    out.set_axes(axes_);
    if (axes_.axis == SearchAxis::kOblique) {
      // The search image's corners lie outside the frame, where it continues the frame's edge:
      // a point there, or within a laser width of the edge (where the line's profile is cut), is
      // not seen.
      constexpr double kEdge = 1.5;
      const double last_x = width_ - 1 - kEdge, last_y = height_ - 1 - kEdge;
      out.keep_if([&](const ProfilePoint& p) {
        const auto [x, y] = axes_.to_image(p.u, p.v);
        return x >= kEdge && x <= last_x && y >= kEdge && y <= last_y;
      });
    }
    if (!region_.whole()) {
      // The search region holds the frame's; its sub-pixel points may stray out of it by a
      // little (and an oblique one holds more).
      const DetectionRegion in_frame = region();
      out.keep_if([&](const ProfilePoint& p) {
        const auto [x, y] = axes_.to_image(p.u, p.v);
        return in_frame.contains(x, y);
      });
    }
  }

 private:
  // The region in search coordinates: the search image's pixels whose square meets the frame
  // region's (the same rectangle transposed for rows; for oblique axes the rotated one's bounds).
  DetectionRegion search_region() const {
    if (region_.whole()) return region_;
    if (axes_.identity()) return region_.in_frame(frame_width_, frame_height_);
    const DetectionRegion r = region_.in_frame(frame_width_, frame_height_);
    double lo[2] = {HUGE_VAL, HUGE_VAL}, hi[2] = {-HUGE_VAL, -HUGE_VAL};
    for (const double x : {r.x - 0.5, r.x + r.width - 0.5}) {
      for (const double y : {r.y - 0.5, r.y + r.height - 0.5}) {
        const auto corner = axes_.to_search(x, y);
        for (int i = 0; i < 2; ++i) {
          lo[i] = std::min(lo[i], corner[i]);
          hi[i] = std::max(hi[i], corner[i]);
        }
      }
    }
    // A pixel's square meets [lo, hi] from ceil(lo) to floor(hi) when the corners are on half
    // pixels (rows); one more on each side where they are not (oblique).
    const double slack = axes_.axis == SearchAxis::kRows ? 0.0 : 1.0;
    const int limits[2] = {axes_.lines, axes_.length};
    int first[2], last[2];
    for (int i = 0; i < 2; ++i) {
      first[i] = static_cast<int>(std::clamp(std::ceil(lo[i] - slack), 0.0, limits[i] - 1.0));
      last[i] = static_cast<int>(std::clamp(std::floor(hi[i] + slack), 0.0, limits[i] - 1.0));
    }
    return {first[0], first[1], last[0] - first[0] + 1, last[1] - first[1] + 1};
  }

  std::unique_ptr<Detector> detector_;
  SearchAxes axes_;
  int width_, height_;
  int frame_width_ = width_, frame_height_ = height_;  // of the last reset()
  DetectionRegion region_;                             // in the frame's pixels
  SearchImage search_;
};

}  // namespace

std::vector<std::string> detector_names() {
  return {"maxvalue", "fir", "background", "backprojection"};
}

// The detectors proper: points in pixels.
static std::unique_ptr<Detector> make_image_detector(const std::string& name,
                                                     const DetectorOptions& options) {
  if (name == "maxvalue") return std::make_unique<MaxValueDetector>(options.maxvalue_threshold);
  if (name == "fir") return std::make_unique<FirDetector>(options);
  if (name == "background") return std::make_unique<BackgroundDetector>(options);
  if (name == "backprojection") return std::make_unique<BackprojectionDetector>(options);
  return nullptr;
}

std::unique_ptr<Detector> make_detector(const std::string& name, const DetectorOptions& options) {
  options.roi.validate(options.geometry.width, options.geometry.height);
  const SearchAxes axes = choose_search_axes(options.geometry);
  DetectorOptions search_options = options;
  search_options.geometry = search_geometry(options.geometry, axes);
  std::unique_ptr<Detector> detector = make_image_detector(name, search_options);
  if (!detector) return nullptr;
  auto searching =
      std::make_unique<SearchAxesDetector>(std::move(detector), axes, options.geometry);
  searching->set_region(options.roi);
  return with_triangulation(std::move(searching), options.geometry);
}

}  // namespace laserline::pipeline
