#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "pipeline/detector.hpp"

namespace laserline::pipeline {

// The paper's "Max Value" baseline: in every column the brightest pixel, if at least `threshold`,
// is the laser, refined to sub-pixel by a 3-point Gaussian fit. A flat-topped (clipped) maximum
// takes the centre of its run instead. SNR is the peak over the column's mean brightness.
// Fails by design where ambient light outshines the laser; kept as the reference detector.
// Within a region (set_region()) the columns and rows are those of the region: the mean the SNR
// compares with is the region's rows'.
class MaxValueDetector final : public Detector {
 public:
  explicit MaxValueDetector(int threshold);

  const char* name() const override { return "maxvalue"; }
  std::size_t max_points(int width, int /*height*/) const override {
    return static_cast<std::size_t>(width);
  }
  void reset(int width, int height) override;
  // Parts: ranges of columns.
  void use_parts(PartRunner& runner) override { runner_ = &runner; }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;
  void set_region(const DetectionRegion& region) override { region_ = region; }
  DetectionRegion region() const override { return region_.in_frame(width_, height_); }

 private:
  // Columns [begin, end) of the region (in the frame): their points into row_ and snr_db_.
  void columns(const ImageView& image, const DetectionRegion& region, int begin, int end);

  int threshold_;
  DetectionRegion region_;
  int width_ = 0, height_ = 0;
  std::array<float, 256> log_lut_{};
  // Per-column running state of the row-major scan (row-major is what the cache likes).
  std::vector<std::uint8_t> max_value_;
  std::vector<std::uint16_t> first_row_;
  std::vector<std::uint16_t> last_row_;
  std::vector<std::uint32_t> sum_;
  // Per column: its point's row and SNR (NaN: none), before they go into the profile in order.
  std::vector<float> row_, snr_db_;
  PartRunner* runner_ = &one_part();
  int parts_ = 1;
};

}  // namespace laserline::pipeline
