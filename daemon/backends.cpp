#include "daemon/backends.hpp"

#include "hal/registry.hpp"

namespace laserline::daemon {

namespace {

std::string join(const std::vector<std::string>& names) {
  std::string list;
  for (const auto& n : names)
    list += (list.empty() ? "" : ", ") + n;
  return list;
}

}  // namespace

Backends create_backends(DaemonConfig& config) {
  Backends b;
  b.laser = hal::make_laser(config.laser_backend, config.laser_options);
  if (!b.laser) {
    config.laser_options.fail("backend", "unknown laser backend '" + config.laser_backend +
                                             "' (available: " + join(hal::laser_backends()) + ")");
  }
  config.laser_options.finish();

  hal::CameraRequest request{&config.camera_options, &config.calibration, b.laser.get(),
                             config.laser_channel};
  b.camera = hal::make_camera(config.camera_backend, request);
  if (!b.camera) {
    config.camera_options.fail("backend", "unknown camera backend '" + config.camera_backend +
                                              "' (available: " + join(hal::camera_backends()) +
                                              ")");
  }
  config.camera_options.finish();

  check_laser_sheet_in_view(
      config.calibration, config.calibration_source,
      searches_depth_range(config.detector) ? &config.detector_options.frontend : nullptr,
      config.source);
  b.detector = pipeline::make_detector(config.detector, config.detector_options);
  check_frame_path(config, b.camera->format(), *b.detector);
  return b;
}

}  // namespace laserline::daemon
