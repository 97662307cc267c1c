#include "hal/v4l2_camera.hpp"

#include "hal/calibration.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

std::unique_ptr<Camera> create_v4l2_camera(const CameraRequest& request) {
  YamlMap& c = *request.options;
  V4l2CameraOptions o;
  o.device = c.string("device", o.device);
  if (o.device.empty()) c.fail("device", "must name the video device, e.g. /dev/video0");
  o.pixel_format = c.choice("pixel_format", o.pixel_format, v4l2_pixel_formats());
  o.width = static_cast<int>(c.integer("width", request.calibration->camera.width, 1, 65535));
  o.height = static_cast<int>(c.integer("height", request.calibration->camera.height, 1, 65535));
  o.frame_rate_hz = c.number("frame_rate_hz", 30.0, kFrameRateRange.min, kFrameRateRange.max);
  o.buffers = static_cast<int>(c.integer("buffers", o.buffers, 2, 32));
  if (const std::string problem = v4l2_pixel_format_problem(o); !problem.empty()) {
    c.fail("pixel_format", problem);
  }
  o.channel = request.channel;
  o.reconnect_min_ms =
      static_cast<int>(c.integer("reconnect_min_ms", o.reconnect_min_ms, 10, 60000));
  o.reconnect_max_ms = static_cast<int>(
      c.integer("reconnect_max_ms", o.reconnect_max_ms, o.reconnect_min_ms, 600000));
  return std::make_unique<V4l2Camera>(o);
}

namespace {
const CameraBackendRegistration kV4l2{"v4l2", create_v4l2_camera};
}  // namespace

}  // namespace laserline::hal
