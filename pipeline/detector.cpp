#include "pipeline/detector.hpp"

#include "pipeline/backprojection_detector.hpp"
#include "pipeline/frontend_detectors.hpp"
#include "pipeline/maxvalue_detector.hpp"
#include "pipeline/triangulation.hpp"

namespace laserline::pipeline {

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
  return with_triangulation(make_image_detector(name, options), options.geometry);
}

}  // namespace laserline::pipeline
