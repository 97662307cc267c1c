// The simulated scene (SimScene): its options checked, the surface made (sim_surface.cpp), the
// camera's pose per frame (sway, scan, vehicle) and the surface's shape. Rendering is in
// sim_render.cpp, the exact answer in sim_ground_truth.cpp.
#include "hal/sim/sim_scene.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "hal/sim/sim_lines.hpp"
#include "hal/sim/sim_render.hpp"
#include "hal/sim/sim_surface.hpp"

namespace laserline::hal {

using namespace sim;

namespace {

constexpr int kMaxImageSide = 16384;
constexpr int kMaxSnow = 100000;

void validate(const SimSceneOptions& o) {
  const CameraIntrinsics& cam = o.calibration.camera;
  require(cam.width >= 8 && cam.width <= kMaxImageSide && cam.height >= 8 &&
              cam.height <= kMaxImageSide,
          "image size must be between 8 and " + std::to_string(kMaxImageSide) + " pixels");
  require(std::isfinite(cam.fx) && cam.fx > 0 && std::isfinite(cam.fy) && cam.fy > 0,
          "fx and fy must be positive");
  require(std::isfinite(cam.cx) && std::isfinite(cam.cy), "cx and cy must be finite");
  require(!cam.has_distortion(), "the simulated camera has no lens distortion");
  const auto plane = o.calibration.laser.plane_coefficients();
  for (double k : plane)
    require(std::isfinite(k), "laser plane coefficients must be finite");
  require(plane[0] * plane[0] + plane[1] * plane[1] + plane[2] * plane[2] > 1e-18,
          "laser plane normal must not be zero");
  require(finite_nonneg(o.calibration.laser.sheet_width_m), "sheet_width_m must be >= 0");
  require(std::isfinite(o.frame_rate_hz) && o.frame_rate_hz > 0, "frame_rate_hz must be > 0");
  require(std::isfinite(o.distance_m) && o.distance_m > 0, "distance_m must be > 0");
  require(std::isfinite(o.tilt_x_deg) && std::abs(o.tilt_x_deg) < 89.0 &&
              std::isfinite(o.tilt_y_deg) && std::abs(o.tilt_y_deg) < 89.0,
          "tilt_x_deg and tilt_y_deg must be within (-89, 89)");
  require(std::isfinite(o.texture_scale_m) && o.texture_scale_m > 0, "texture_scale_m must be > 0");
  require(finite_nonneg(o.texture_contrast) && o.texture_contrast <= 100,
          "texture_contrast must be within [0, 100]");
  require(finite_nonneg(o.ambient) && finite_nonneg(o.laser_peak) && finite_nonneg(o.blur_px) &&
              finite_nonneg(o.noise_sigma) && finite_nonneg(o.backscatter) &&
              finite_nonneg(o.attenuation_per_m),
          "ambient, laser_peak, blur_px, noise_sigma, backscatter, attenuation_per_m must be >= 0");
  // Grey levels far beyond 8 bit make no sense, and the limits keep the float-to-int conversion
  // of a pixel in range.
  require(o.ambient <= 1e4 && o.laser_peak <= 1e4 && o.backscatter <= 1e4 && o.noise_sigma <= 1e3,
          "ambient, laser_peak and backscatter must be <= 1e4, noise_sigma <= 1e3");
  require(finite_nonneg(o.forward_scatter) && o.forward_scatter <= 1 && finite_nonneg(o.veiling) &&
              o.veiling <= 1,
          "forward_scatter and veiling must be within [0, 1]");
  require(std::isfinite(o.caustic_peak) && o.caustic_peak >= 1 && o.caustic_peak <= 100,
          "caustic_peak must be within [1, 100]");
  for (std::size_t c = 0; c < 3; ++c) {
    require(finite_nonneg(o.laser_rgb[c]) && o.laser_rgb[c] <= 10 &&
                finite_nonneg(o.ambient_rgb[c]) && o.ambient_rgb[c] <= 10,
            "laser_rgb and ambient_rgb must be within [0, 10]");
  }
  require(finite_nonneg(o.scatter_halo_px) && o.scatter_halo_px <= 1000,
          "scatter_halo_px must be within [0, 1000]");
  require(std::isfinite(o.caustic_scale_m) && o.caustic_scale_m >= 0.01 &&
              o.caustic_scale_m <= 100 && std::isfinite(o.caustic_speed_m_s) &&
              std::abs(o.caustic_speed_m_s) <= 100,
          "caustic_scale_m must be within [0.01, 100], caustic_speed_m_s within [-100, 100]");
  require(o.snow_per_frame >= 0 && o.snow_per_frame <= kMaxSnow,
          "snow_per_frame must be within [0, " + std::to_string(kMaxSnow) + "]");
  require(std::isfinite(o.snow_size_px) && o.snow_size_px > 0 && o.snow_size_px <= 50 &&
              finite_nonneg(o.snow_brightness) && o.snow_brightness <= 100 &&
              std::isfinite(o.snow_min_depth_m) && o.snow_min_depth_m > 0,
          "snow_size_px must be within (0, 50], snow_brightness within [0, 100], "
          "snow_min_depth_m > 0");
  require(finite_nonneg(o.marks_per_m2) && o.marks_per_m2 <= 10000 &&
              finite_nonneg(o.marks_albedo) && o.marks_albedo <= 100,
          "marks_per_m2 must be within [0, 10000], marks_albedo within [0, 100]");
  require(finite_nonneg(o.sway_m) && finite_nonneg(o.sway_deg), "sway_m and sway_deg must be >= 0");
  require(std::isfinite(o.sway_period_s) && o.sway_period_s > 0, "sway_period_s must be > 0");
  require(finite_nonneg(o.scan_rate_deg_s) && o.scan_rate_deg_s <= 1000,
          "scan_rate_deg_s must be within [0, 1000]");
  require(finite_nonneg(o.scan_amplitude_deg) && o.scan_amplitude_deg <= 45,
          "scan_amplitude_deg must be within [0, 45]");
  require(finite_nonneg(o.relief_height_m) && o.relief_height_m <= 0.5 * o.distance_m,
          "relief_height_m must be within [0, distance_m / 2]");
  require(finite_nonneg(o.relief_min_height_m) &&
              (o.relief_height_m == 0 || o.relief_min_height_m <= o.relief_height_m),
          "relief_min_height_m must be within [0, relief_height_m]");
  require(finite_nonneg(o.relief_per_m2) && o.relief_per_m2 <= 100,
          "relief_per_m2 must be within [0, 100]");
  require(
      std::isfinite(o.relief_max_slope) && o.relief_max_slope >= 0.05 && o.relief_max_slope <= 1.0,
      "relief_max_slope must be within [0.05, 1]");
  // The widest feature (a pile 1.28 m long plus two flanks of 1.4 (pi / 2) height / slope)
  // must fit in the relief tile with room to spare.
  require(o.relief_height_m <= 0.72 * o.relief_max_slope,
          "relief_height_m / relief_max_slope must be <= 0.72 m (features must fit the 5.12 m "
          "relief tile)");
  require(std::isfinite(o.vehicle_speed_m_s) && std::abs(o.vehicle_speed_m_s) <= 10 &&
              std::isfinite(o.object_speed_m_s) && std::abs(o.object_speed_m_s) <= 10,
          "vehicle_speed_m_s and object_speed_m_s must be within [-10, 10]");
}

}  // namespace

SimScene::SimScene(const SimSceneOptions& options) : options_(options) {
  validate(options_);
  lines_ = epipolar_lines(options_.calibration);
  const auto width = static_cast<std::size_t>(options_.calibration.camera.width);
  const auto lines = static_cast<std::size_t>(lines_.count);
  texture_ = make_texture(options_);
  paint_checkerboard(texture_, options_);
  if (options_.caustic_peak > 1) {
    caustics_ = make_caustics(options_.seed, options_.caustic_peak, caustic_mean_);
  }
  noise_ = make_noise_table(options_.seed);
  // One image row, then the glow floor of each of its pixels, each padded to whole kernel blocks;
  // the padding never glows.
  const std::size_t padded = (width + kBlock - 1) / kBlock * kBlock;
  row_buffer_.assign(4 * padded, kNoGlow);
  if (options_.colour != SimColour::kMono) channel_rows_.assign(3 * padded, 0);
  scratch_truth_.lines = lines_;
  scratch_truth_.position.assign(lines, kNaN);
  scratch_truth_.depth_m.assign(lines, kNaN);
  scratch_truth_.width_px.assign(lines, kNaN);
  line_gain_.assign(lines, 0.0f);
  glow_floor_.assign(std::max(lines, padded), kNoGlow);
  if (options_.relief_height_m > 0 && options_.relief_per_m2 > 0) relief_ = make_relief(options_);
  snow_.reserve(static_cast<std::size_t>(options_.snow_per_frame));
}

FrameFormat SimScene::format() const {
  const CameraIntrinsics& cam = options_.calibration.camera;
  return FrameFormat{cam.width, cam.height, cam.width, PixelFormat::kMono8};
}

SourceFormat SimScene::raw_format() const {
  SourceFormat f;
  switch (options_.colour) {
    case SimColour::kMono:
      f.layout = PixelLayout::kMono;
      break;
    case SimColour::kRgb:
      f.layout = PixelLayout::kRgb;
      break;
    case SimColour::kBayerRggb:
      f.layout = PixelLayout::kBayerRggb;
      break;
    case SimColour::kBayerGrbg:
      f.layout = PixelLayout::kBayerGrbg;
      break;
    case SimColour::kBayerGbrg:
      f.layout = PixelLayout::kBayerGbrg;
      break;
    case SimColour::kBayerBggr:
      f.layout = PixelLayout::kBayerBggr;
      break;
  }
  return f;
}

std::size_t SimScene::raw_bytes() const {
  const CameraIntrinsics& cam = options_.calibration.camera;
  return static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height) *
         static_cast<std::size_t>(raw_format().bytes_per_pixel());
}

SimScene::Pose SimScene::pose_at(std::uint64_t sequence) const {
  const double time = static_cast<double>(sequence) / options_.frame_rate_hz;
  const double phase = 2.0 * kPi / options_.sway_period_s * time;
  // Sinusoids shifted to start at zero, so that the world frame is the camera frame at t = 0.
  auto wave = [](double x, double shift) { return std::sin(x + shift) - std::sin(shift); };
  Pose pose;
  pose.t = Vec3(options_.sway_m * wave(phase, 0.0), options_.sway_m * 0.6 * wave(1.3 * phase, 1.0),
                options_.sway_m * 0.4 * wave(0.7 * phase, 2.0));
  if (options_.vehicle_speed_m_s != 0) {
    // Along the surface's x axis (see make_geometry), so the distance to the surface stays.
    const Mat3 basis = rot_x(options_.tilt_x_deg * kDeg) * rot_y(options_.tilt_y_deg * kDeg);
    const double travel = options_.vehicle_speed_m_s * time;
    pose.t += travel * basis.col(0);
  }
  const double amp = options_.sway_deg * kDeg;
  double scan = 0.0;
  if (options_.scan_rate_deg_s > 0 && options_.scan_amplitude_deg > 0) {
    // Triangle wave: 0 -> +A -> -A -> 0 over a period of 4 A / rate.
    const double a = options_.scan_amplitude_deg;
    const double x = std::fmod(options_.scan_rate_deg_s * time + a, 4.0 * a);  // in [0, 4A)
    scan = (x < 2.0 * a ? x - a : 3.0 * a - x) * kDeg;
  }
  const double ax = amp * wave(0.9 * phase, 0.5) + (options_.scan_pan ? 0.0 : scan);
  const double ay = amp * 0.7 * wave(1.1 * phase, 2.3) + (options_.scan_pan ? scan : 0.0);
  const double az = amp * 0.5 * wave(0.8 * phase, 4.1);
  pose.r = rot_z(az) * (rot_y(ay) * rot_x(ax));
  return pose;
}

SimCameraPose SimScene::camera_pose(std::uint64_t sequence) const {
  const Pose pose = pose_at(sequence);  // camera -> world
  SimCameraPose out;
  out.rotation = pose.r.transpose();
  out.translation = -(pose.r.transpose() * pose.t);
  return out;
}

double SimScene::relief_height(double x_m, double y_m) const {
  return relief_.empty() ? 0.0 : relief_at(relief_.data(), x_m, y_m);
}

Vec3 SimScene::surface_point(double x_m, double y_m) const {
  const Mat3 basis = rot_x(options_.tilt_x_deg * kDeg) * rot_y(options_.tilt_y_deg * kDeg);
  const double h = relief_height(x_m, y_m);
  // Axes e1, e2 are the basis' first two columns, the normal toward the camera minus the third.
  Vec3 out = x_m * basis.col(0) + y_m * basis.col(1) - h * basis.col(2);
  out[2] += options_.distance_m;
  return out;
}

}  // namespace laserline::hal
