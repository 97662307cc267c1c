#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "pipeline/detector.hpp"
#include "pipeline/frontend.hpp"
#include "pipeline/motion.hpp"

namespace laserline::pipeline {

// The paper's "FIR" detector: width normalisation, band-pass, SNR, thresholding and peaks on the
// frame itself (no background subtraction). Robust to backscatter; texture lit by ambient light
// gives false candidates.
class FirDetector final : public Detector {
 public:
  explicit FirDetector(const DetectorOptions& options);
  const char* name() const override { return "fir"; }
  std::size_t max_points(int width, int height) const override;
  void reset(int width, int height) override;
  void use_parts(PartRunner& runner) override { frontend_.use_parts(runner); }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;
  void set_region(const DetectionRegion& region) override { frontend_.set_region(region); }
  DetectionRegion region() const override { return frontend_.region(); }

  const Frontend& frontend() const { return frontend_; }

 private:
  Frontend frontend_;
};

// The paper's "Background" detector: an earlier frame, warped onto this one by the homography
// estimated from tracked features (III-A), is subtracted before the FIR stages. Which frame
// (BackgroundOptions): the most recent laser-off frame (with the laser alternating: the classic
// on/off subtraction, motion compensated); else the most recent frame the scene has moved far
// enough from across the laser line that its line does not lie on this one's (the previous frame
// while the unit scans); else none: a frame without a motion estimate (the first, a dark or
// featureless one) or a still camera (hovering, a fixed rig) is searched as it is, as by `fir`.
// In turbid water the laser lights the water in front of the surface: a glow that ends at the
// line and moves with the camera, not the scene; a background warped toward that side would lay
// its glow over the line, so then only one warped the other way is used. Each profile says which
// frame it subtracted. Laser-off frames give no points. Keeps a copy of the last history_frames
// frames (of the rows the warp can reach).
class BackgroundDetector final : public Detector {
 public:
  // estimate_camera_motion: the motion estimate also gives the camera's rotation and translation
  // (the essential matrix, from the geometry's intrinsics), for the validation of Section IV.
  explicit BackgroundDetector(const DetectorOptions& options, bool estimate_camera_motion = false);
  const char* name() const override { return "background"; }
  std::size_t max_points(int width, int height) const override;
  void reset(int width, int height) override;
  void use_parts(PartRunner& runner) override;
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;
  // The front-end's search (the motion is estimated over the whole frame).
  void set_region(const DetectionRegion& region) override { frontend_.set_region(region); }
  DetectionRegion region() const override { return frontend_.region(); }
  // detect() in two steps, for a validation in between (BackprojectionDetector): the frame's
  // candidates, all eligible (Frontend::collect_candidates()); then the line among those still
  // eligible (Frontend::select_line()), in the same frame (where the line's width is measured).
  void collect_candidates(const ImageView& image, const FrameContext& frame, Profile& out);
  void select_line(const ImageView& image, Profile& out);

  const Frontend& frontend() const { return frontend_; }
  const MotionEstimator& motion() const { return motion_; }
  const MotionEstimate& last_motion() const { return last_motion_; }

 private:
  // A frame kept as a candidate background: the rows the warp can reach.
  struct History {
    std::vector<std::uint8_t> rows;
    std::uint64_t sequence = 0;
    bool laser_on = false;
    bool usable = false;    // its motion to the current frame is known
    Homography to_history;  // a current frame's pixel -> where it was in this frame
    // Per epipolar line: where this frame's own line was found, NaN where it was not; and on
    // how many lines it was.
    std::vector<float> line;
    int line_points = 0;
  };
  // The background for the current frame `image`: none (history nullptr), a kept frame as it
  // is, or the newest kept frame less its own line.
  struct Background {
    const History* history = nullptr;
    bool own_line_removed = false;
  };
  Background choose_background(const ImageView& image) const;
  // `h`'s rows into own_line_removed_: about its line (a band of twice the width the line moves
  // by, plus a row either side), no brighter than the brighter of the rows just beyond (the
  // surface there, without the laser's light); on epipolar lines where it found no line, or where
  // the band leaves the rows kept, 0 (nothing is subtracted there: a line it missed would
  // otherwise take this frame's away, and the next frame's, for as long as the scene holds).
  void remove_own_line(const History& h);
  // Whether subtracting `h` from `image` takes away more of what lies beside the line than it
  // adds: beside the points where the line was last found, the frame less the warped background
  // against the frame less itself two line widths along (texture and noise). Where the scene holds
  // still, texture cancels; where it is dark and plain, the background only adds its noise.
  bool subtraction_clears(const History& h, const ImageView& image) const;
  // How far the scene moved across the line between `h` and the current frame, in line widths,
  // at the points where the line was last seen (or across the rows searched): the least (0 where
  // the line's points moved one way at some and the other way at others), and the least toward
  // the far side of the line (negative where it moved toward the near side).
  struct Motion {
    double across = 0, toward_far = 0;
  };
  Motion motion_across_line(const History& h) const;
  // The line's width across itself (full width at half maximum) in `image` at the points where it
  // was just found, against the width the model predicts there: the median, and the median of the
  // last three frames'. A line blurred or bloomed to more than three times the model must move by
  // its own extent (1.5 times that width) before an earlier frame's line leaves it alone;
  // narrower, the model's width is what it moves by (motion_across_line()).
  void measure_line_width(const ImageView& image);

  Frontend frontend_;
  ScannerGeometry geometry_;
  BackgroundOptions options_;
  bool estimate_camera_motion_ = false;
  MotionEstimator motion_;
  MotionEstimate last_motion_;
  std::vector<History> history_;
  // The current frame's kept rows, copied in parts while its detection runs; then a History's
  // (the buffers are swapped).
  std::vector<std::uint8_t> incoming_;
  std::vector<std::uint8_t> own_line_removed_;  // remove_own_line()'s rows
  std::vector<std::uint8_t> line_kept_;         // remove_own_line(): per line, 0xff or 0
  PartRunner* runner_ = &one_part();
  int parts_ = 1;
  int newest_ = -1;                       // index in history_ of the last frame kept
  std::array<double, 3> width_ratios_{};  // measure_line_width(): the last three frames'
  std::size_t width_ratio_next_ = 0, width_ratio_count_ = 0;
  double motion_width_scale_ = 1.0;     // the model's width -> the width the line moves by
  int band_first_ = 0, band_rows_ = 0;  // which rows of a frame are kept
  int width_ = 0, height_ = 0;
};

}  // namespace laserline::pipeline
