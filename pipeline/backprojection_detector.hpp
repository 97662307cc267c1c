#pragma once

#include <cstdint>

#include "pipeline/detector.hpp"
#include "pipeline/frontend_detectors.hpp"
#include "pipeline/validation.hpp"

namespace laserline::pipeline {

// The paper's "Back-Projection" detector: the `background` detector (III-A to III-E) followed by
// the validation of Section IV. Its candidates are segmented, tracked over frames n-2, n-1, n,
// triangulated with the camera motion and back-projected: the points of segments that move like
// the static scene are kept in the profile not valid (rejected), as are candidates in no segment.
// Latency: the profile of frame n is given when frame n is processed, from frames n-2, n-1 and n;
// the same every frame (the first two frames after reset() are not validated against the scene).
// Thread context: one thread at a time per instance.
class BackprojectionDetector final : public Detector {
 public:
  explicit BackprojectionDetector(const DetectorOptions& options);
  const char* name() const override { return "backprojection"; }
  std::size_t max_points(int width, int height) const override;
  void reset(int width, int height) override;
  void use_parts(PartRunner& runner) override { background_.use_parts(runner); }
  void detect(const ImageView& image, const FrameContext& frame, Profile& out) override;
  // The candidates' region: a segment that leaves it is validated on its part inside.
  void set_region(const DetectionRegion& region) override { background_.set_region(region); }
  DetectionRegion region() const override { return background_.region(); }

  const BackgroundDetector& background() const { return background_; }
  const LineValidator& validator() const { return validator_; }

 private:
  BackgroundDetector background_;
  LineValidator validator_;
};

}  // namespace laserline::pipeline
