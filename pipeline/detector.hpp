#pragma once

#include <memory>
#include <string>
#include <vector>

#include "pipeline/image_view.hpp"
#include "pipeline/profile.hpp"

namespace laserline::pipeline {

// Options of every detector, filled from the configuration. Each detector reads its own part.
struct DetectorOptions {
  // maxvalue: a column's maximum is a laser point when it is at least this bright (grey level).
  int maxvalue_threshold = 40;
};

// Finds laser points in one frame. Epipolar lines are image columns, so a detector looks for the
// laser along each column. reset() sizes every buffer for a frame size (allocates); detect() then
// does not allocate and its work is bounded by the image size.
// Thread context: one thread at a time per instance.
class Detector {
 public:
  virtual ~Detector() = default;
  virtual const char* name() const = 0;
  // Most points one frame can produce (capacity the caller gives the output Profile).
  virtual std::size_t max_points(int width, int height) const = 0;
  virtual void reset(int width, int height) = 0;
  virtual void detect(const ImageView& image, Profile& out) = 0;
};

std::vector<std::string> detector_names();
// nullptr for an unknown name.
std::unique_ptr<Detector> make_detector(const std::string& name, const DetectorOptions& options);

}  // namespace laserline::pipeline
