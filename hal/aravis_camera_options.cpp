#include "hal/aravis_camera.hpp"

#include "hal/calibration.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

std::unique_ptr<Camera> create_aravis_camera(const CameraRequest& request) {
  YamlMap& c = *request.options;
  AravisCameraOptions o;
  o.device = c.string("device", o.device);
  o.pixel_format = c.choice("pixel_format", o.pixel_format, aravis_pixel_formats());
  o.width = static_cast<int>(c.integer("width", request.calibration->camera.width, 1, 65535));
  o.height = static_cast<int>(c.integer("height", request.calibration->camera.height, 1, 65535));
  o.offset_x = static_cast<int>(c.integer("offset_x", 0, 0, 65535));
  o.offset_y = static_cast<int>(c.integer("offset_y", 0, 0, 65535));
  o.frame_rate_hz = c.number("frame_rate_hz", 30.0, kFrameRateRange.min, kFrameRateRange.max);
  o.exposure_us =
      c.number("exposure_us", o.exposure_us, kAravisExposureRange.min, kAravisExposureRange.max);
  o.gain_db = c.number("gain_db", o.gain_db, kAravisGainRange.min, kAravisGainRange.max);
  o.packet_size = static_cast<int>(c.integer("packet_size", o.packet_size, -1, 65535));
  o.packet_delay_ns = c.integer("packet_delay_ns", o.packet_delay_ns, -1, 1'000'000'000);
  o.buffers = static_cast<int>(c.integer("buffers", o.buffers, 2, 1024));
  const std::string trigger = c.choice("trigger", "free", {"free", "software", "line"});
  o.trigger = trigger == "free"       ? AravisTrigger::kFreeRun
              : trigger == "software" ? AravisTrigger::kSoftware
                                      : AravisTrigger::kLine;
  o.trigger_source = c.string("trigger_source", o.trigger_source);
  if (c.has("features")) {
    const YAML::Node features = c.node("features");
    if (!features.IsMap()) c.fail("features", "must be a mapping of GenICam feature: value");
    for (const auto& f : features) {
      if (!f.second.IsScalar()) {
        c.fail("features", "'" + f.first.as<std::string>() + "' must have a single value");
      }
      o.features.emplace_back(f.first.as<std::string>(), f.second.Scalar());
    }
  }
  if (const std::string problem = aravis_pixel_format_problem(o); !problem.empty()) {
    c.fail("pixel_format", problem);
  }
  o.channel = request.channel;
  o.lost_after_ms = static_cast<int>(c.integer("lost_after_ms", o.lost_after_ms, 100, 60000));
  o.reconnect_min_ms =
      static_cast<int>(c.integer("reconnect_min_ms", o.reconnect_min_ms, 10, 60000));
  o.reconnect_max_ms = static_cast<int>(
      c.integer("reconnect_max_ms", o.reconnect_max_ms, o.reconnect_min_ms, 600000));
  return std::make_unique<AravisCamera>(o);
}

namespace {
const CameraBackendRegistration kAravis{"aravis", create_aravis_camera};
}  // namespace

}  // namespace laserline::hal
