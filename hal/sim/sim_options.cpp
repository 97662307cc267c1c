#include "hal/sim/sim_options.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include "hal/registry.hpp"
#include "hal/sim/sim_camera.hpp"
#include "hal/sim/sim_laser.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

SimSceneOptions read_sim_options(YamlMap& sim, const Calibration& calibration,
                                 double frame_rate_hz) {
  SimSceneOptions o;
  o.calibration = calibration;
  if (calibration.camera.has_distortion()) {
    sim.fail("", "the simulator renders an ideal pinhole camera; set calibration distortion to 0");
  }
  o.frame_rate_hz = frame_rate_hz;
  o.seed = static_cast<std::uint64_t>(sim.integer("seed", 1, 0, INT64_MAX));
  o.distance_m = sim.number("distance_m", o.distance_m, 0.1, 100.0);
  o.tilt_x_deg = sim.number("tilt_x_deg", o.tilt_x_deg, -60.0, 60.0);
  o.tilt_y_deg = sim.number("tilt_y_deg", o.tilt_y_deg, -60.0, 60.0);
  o.texture_scale_m = sim.number("texture_scale_m", o.texture_scale_m, 1e-4, 10.0);
  o.texture_contrast = sim.number("texture_contrast", o.texture_contrast, 0.0, 1.0);
  o.ambient = sim.number("ambient", o.ambient, 0.0, 255.0);
  o.laser_peak = sim.number("laser_peak", o.laser_peak, 0.0, 1000.0);
  o.blur_px = sim.number("blur_px", o.blur_px, 0.0, 20.0);
  o.noise_sigma = sim.number("noise_sigma", o.noise_sigma, 0.0, 50.0);
  o.backscatter = sim.number("backscatter", o.backscatter, 0.0, 255.0);
  o.attenuation_per_m = sim.number("attenuation_per_m", o.attenuation_per_m, 0.0, 10.0);
  o.sway_m = sim.number("sway_m", o.sway_m, 0.0, 1.0);
  o.sway_deg = sim.number("sway_deg", o.sway_deg, 0.0, 20.0);
  o.sway_period_s = sim.number("sway_period_s", o.sway_period_s, 0.1, 3600.0);
  o.scan_rate_deg_s = sim.number("scan_rate_deg_s", o.scan_rate_deg_s, 0.0, 1000.0);
  o.scan_amplitude_deg = sim.number("scan_amplitude_deg", o.scan_amplitude_deg, 0.0, 45.0);
  o.relief_height_m = sim.number("relief_height_m", o.relief_height_m, 0.0, 0.5 * o.distance_m);
  o.relief_min_height_m =
      sim.number("relief_min_height_m", std::min(o.relief_min_height_m, o.relief_height_m), 0.0,
                 o.relief_height_m);
  o.relief_per_m2 = sim.number("relief_per_m2", o.relief_per_m2, 0.0, 100.0);
  o.relief_max_slope = sim.number("relief_max_slope", o.relief_max_slope, 0.05, 1.0);
  if (o.relief_height_m > 0.72 * o.relief_max_slope) {
    char least[32];
    std::snprintf(least, sizeof least, "%.3f", std::ceil(o.relief_height_m / 0.72 * 1000) / 1000);
    sim.fail("relief_max_slope", std::string("must be at least relief_height_m / 0.72 = ") + least +
                                     " (features must fit the 5.12 m relief tile)");
  }
  o.vehicle_speed_m_s = sim.number("vehicle_speed_m_s", o.vehicle_speed_m_s, -10.0, 10.0);
  o.object_speed_m_s = sim.number("object_speed_m_s", o.object_speed_m_s, -10.0, 10.0);
  o.scan_pan = sim.boolean("scan_pan", o.scan_pan);
  o.forward_scatter = sim.number("forward_scatter", o.forward_scatter, 0.0, 1.0);
  o.scatter_halo_px = sim.number("scatter_halo_px", o.scatter_halo_px, 0.0, 1000.0);
  o.veiling = sim.number("veiling", o.veiling, 0.0, 1.0);
  o.caustic_peak = sim.number("caustic_peak", o.caustic_peak, 1.0, 100.0);
  o.caustic_scale_m = sim.number("caustic_scale_m", o.caustic_scale_m, 0.01, 100.0);
  o.caustic_speed_m_s = sim.number("caustic_speed_m_s", o.caustic_speed_m_s, -100.0, 100.0);
  o.snow_per_frame = static_cast<int>(sim.integer("snow_per_frame", o.snow_per_frame, 0, 100000));
  o.snow_size_px = sim.number("snow_size_px", o.snow_size_px, 0.1, 50.0);
  o.snow_brightness = sim.number("snow_brightness", o.snow_brightness, 0.0, 100.0);
  o.snow_min_depth_m = sim.number("snow_min_depth_m", o.snow_min_depth_m, 0.01, 100.0);
  o.marks_per_m2 = sim.number("marks_per_m2", o.marks_per_m2, 0.0, 10000.0);
  o.laser_fan_deg = sim.number("laser_fan_deg", o.laser_fan_deg, 0.0, 179.0);
  o.marks_albedo = sim.number("marks_albedo", o.marks_albedo, 0.0, 100.0);
  const std::string colour = sim.choice(
      "colour", "mono", {"mono", "rgb", "bayer_rggb", "bayer_grbg", "bayer_gbrg", "bayer_bggr"});
  o.colour = colour == "rgb"          ? SimColour::kRgb
             : colour == "bayer_rggb" ? SimColour::kBayerRggb
             : colour == "bayer_grbg" ? SimColour::kBayerGrbg
             : colour == "bayer_gbrg" ? SimColour::kBayerGbrg
             : colour == "bayer_bggr" ? SimColour::kBayerBggr
                                      : SimColour::kMono;
  for (const auto& [key, rgb] :
       {std::pair{"laser_rgb", &o.laser_rgb}, std::pair{"ambient_rgb", &o.ambient_rgb}}) {
    const std::vector<double> values = sim.numbers(key, {3});
    for (std::size_t c = 0; c < values.size(); ++c) {
      if (!(values[c] >= 0 && values[c] <= 10)) sim.fail(key, "each value must be within 0..10");
      (*rgb)[c] = values[c];
    }
  }
  return o;
}

// Colour scenes (camera.sim.colour) reach the pipeline as request.channel of them.
std::unique_ptr<Camera> create_sim_camera(const CameraRequest& request) {
  return make_sim_camera(request);
}

std::unique_ptr<SimCamera> make_sim_camera(const CameraRequest& request) {
  const double rate =
      request.options->number("frame_rate_hz", 30.0, kFrameRateRange.min, kFrameRateRange.max);
  YamlMap sim = request.options->map("sim");
  SimSceneOptions options = read_sim_options(sim, *request.calibration, rate);
  SimCameraStall stall;
  stall.after_s = sim.number("stall_after_s", 0.0, 0.0, 1e6);
  stall.for_s = sim.number("stall_for_s", 0.0, 0.0, 1e6);
  SimCameraExposure exposure;
  exposure.exposure_us =
      sim.number("exposure_us", exposure.exposure_us, kSimExposureRange.min, kSimExposureRange.max);
  exposure.gain_db = sim.number("gain_db", exposure.gain_db, kSimGainRange.min, kSimGainRange.max);
  sim.finish();
  return std::make_unique<SimCamera>(options, request.laser, stall, request.channel, exposure);
}

std::unique_ptr<Laser> create_sim_laser(YamlMap& /*options*/) {
  return std::make_unique<SimLaser>();
}

namespace {
const CameraBackendRegistration kSimCamera{"sim", create_sim_camera};
const LaserBackendRegistration kSimLaser{"sim", create_sim_laser};
}  // namespace

}  // namespace laserline::hal
