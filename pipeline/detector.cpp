#include "pipeline/detector.hpp"

#include "pipeline/maxvalue_detector.hpp"

namespace laserline::pipeline {

std::vector<std::string> detector_names() {
  return {"maxvalue"};
}

std::unique_ptr<Detector> make_detector(const std::string& name, const DetectorOptions& options) {
  if (name == "maxvalue") return std::make_unique<MaxValueDetector>(options.maxvalue_threshold);
  return nullptr;
}

}  // namespace laserline::pipeline
