#include "daemon/backends.hpp"

#include "daemon/lcm_camera.hpp"
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
  register_lcm_camera();
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

  const hal::FrameFormat format = b.camera->format();
  if (format.width != config.calibration.camera.width ||
      format.height != config.calibration.camera.height) {
    throw hal::ConfigError(config.source + ": calibration.camera: size " +
                           std::to_string(config.calibration.camera.width) + "x" +
                           std::to_string(config.calibration.camera.height) +
                           " differs from the camera's " + std::to_string(format.width) + "x" +
                           std::to_string(format.height));
  }

  const RawFrameOptions& raw = config.raw_frames;
  if (raw.roi_width > 0 &&
      (raw.roi_x + raw.roi_width > format.width || raw.roi_y + raw.roi_height > format.height)) {
    throw hal::ConfigError(config.source + ": lcm.image_roi: [" + std::to_string(raw.roi_x) + ", " +
                           std::to_string(raw.roi_y) + ", " + std::to_string(raw.roi_width) + ", " +
                           std::to_string(raw.roi_height) + "] is not inside the camera's " +
                           std::to_string(format.width) + "x" + std::to_string(format.height) +
                           " frame");
  }
  const int roi_w = raw.roi_width > 0 ? raw.roi_width : format.width;
  const int roi_h = raw.roi_height > 0 ? raw.roi_height : format.height;
  if (roi_w < raw.downscale || roi_h < raw.downscale) {
    throw hal::ConfigError(
        config.source + ": lcm.image_downscale: " + std::to_string(raw.downscale) +
        " leaves no pixel of a " + std::to_string(roi_w) + "x" + std::to_string(roi_h) + " region");
  }

  check_laser_sheet_in_view(
      config.calibration, config.calibration_source,
      searches_depth_range(config.detector) ? &config.detector_options.frontend : nullptr,
      config.source);
  b.detector = pipeline::make_detector(config.detector, config.detector_options);
  return b;
}

}  // namespace laserline::daemon
