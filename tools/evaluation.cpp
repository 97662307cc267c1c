#include "tools/evaluation.hpp"

#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "daemon/config.hpp"

namespace laserline::tools {

std::vector<Scenario> standard_scenarios(int width, int height) {
  hal::SimSceneOptions base;
  hal::CameraIntrinsics& cam = base.calibration.camera;
  const double scale = width / 1280.0;
  cam.width = width;
  cam.height = height;
  cam.fx = cam.fy = 1400.0 * scale;
  cam.cx = (width - 1) / 2.0;
  cam.cy = (height - 1) / 2.0;
  base.frame_rate_hz = 30.0;
  base.distance_m = 1.2;
  base.tilt_y_deg = 8.0;
  base.sway_m = 0.01;
  base.sway_deg = 0.3;
  // A pan-tilt unit sweeping the scene: about 8 px of scene motion per frame across the line.
  base.scan_rate_deg_s = 10.0;
  base.scan_amplitude_deg = 10.0;

  std::vector<Scenario> out;
  {
    Scenario s{"clean", "moderate ambient light, clear water", base};
    s.scene.ambient = 40;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 180;
    s.scene.noise_sigma = 1.5;
    out.push_back(s);
  }
  {
    Scenario s{"ambient", "texture as bright as the laser peak (daylight on a textured pier)",
               base};
    s.scene.ambient = 150;
    s.scene.texture_contrast = 0.6;
    s.scene.laser_peak = 100;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 7;
    out.push_back(s);
  }
  {
    Scenario s = out.back();
    s.name = "ambient-alternate";
    s.description = "as ambient, laser on/off every frame (motion-compensated on/off subtraction)";
    s.alternate = true;
    out.push_back(s);
  }
  {
    Scenario s{"pier",
               "ambient as bright as the laser on a pier with bumps and piles of 5-30 cm; the "
               "vehicle moves along it at 0.4 m/s while the PTU scans (parallax)",
               base};
    s.scene.ambient = 150;
    s.scene.texture_contrast = 0.6;
    s.scene.laser_peak = 100;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 5;
    s.scene.relief_height_m = 0.30;
    s.scene.relief_min_height_m = 0.05;
    s.scene.relief_per_m2 = 1.0;
    s.scene.relief_max_slope = 0.9;
    s.scene.vehicle_speed_m_s = 0.4;
    out.push_back(s);
  }
  {
    Scenario s{"backscatter", "turbid water: glow of the sheet in the water, weak line", base};
    s.scene.ambient = 15;
    s.scene.texture_contrast = 0.3;
    s.scene.laser_peak = 30;
    s.scene.backscatter = 40;
    s.scene.attenuation_per_m = 0.3;
    s.scene.noise_sigma = 2.5;
    s.scene.seed = 3;
    out.push_back(s);
  }
  {
    Scenario s{"clipped", "laser far brighter than the sensor range: saturated core", base};
    s.scene.ambient = 40;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 700;
    s.scene.noise_sigma = 1.5;
    s.scene.seed = 5;
    out.push_back(s);
  }
  {
    Scenario s{"dark", "deep water at night: no ambient light, the laser and sensor noise only",
               base};
    s.scene.ambient = 0;
    s.scene.laser_peak = 120;
    s.scene.attenuation_per_m = 0.1;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 17;
    out.push_back(s);
  }
  for (const char* light : {"", "-daylight"}) {
    const bool daylight = light[0] != 0;
    Scenario s{std::string("hover") + light,
               std::string(daylight ? "daylight as bright as the laser on a textured wall"
                                    : "moderate light on a textured wall") +
                   ", the vehicle holding station without scanning: it sways by a centimetre "
                   "and a few tenths of a degree over seconds, under a pixel between frames",
               base};
    s.scene.ambient = daylight ? 150 : 40;
    s.scene.texture_contrast = daylight ? 0.6 : 0.5;
    s.scene.laser_peak = daylight ? 100 : 160;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 19;
    s.scene.scan_rate_deg_s = 0;
    out.push_back(s);
    if (daylight) {
      s.name = "hover-daylight-alternate";
      s.description = "as hover-daylight, the laser on and off every other frame";
      s.alternate = true;
      out.push_back(s);
    }
  }
  {
    Scenario s{"static-rig",
               "a fixed rig in a lit tank: the wall stays, objects of 5-15 cm on it move past at "
               "5 cm/s",
               base};
    s.scene.ambient = 100;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 120;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 23;
    s.scene.scan_rate_deg_s = 0;
    s.scene.sway_m = 0;
    s.scene.sway_deg = 0;
    s.scene.relief_height_m = 0.15;
    s.scene.relief_min_height_m = 0.05;
    s.scene.relief_per_m2 = 2.0;
    s.scene.relief_max_slope = 0.7;
    s.scene.object_speed_m_s = 0.05;
    out.push_back(s);
  }
  {
    Scenario s{"caustics",
               "sunlit shallow water: caustics drift over a wall with bright paint marks and "
               "shells while the unit scans",
               base};
    s.scene.ambient = 100;
    s.scene.texture_contrast = 0.6;
    s.scene.laser_peak = 110;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 29;
    s.scene.caustic_peak = 2.5;
    s.scene.caustic_scale_m = 0.2;
    s.scene.caustic_speed_m_s = 0.3;
    s.scene.marks_per_m2 = 40;
    s.scene.marks_albedo = 2.5;
    out.push_back(s);
  }
  {
    Scenario s{"marine-snow",
               "a night dive in turbid water: particles lit where they cross the sheet in front "
               "of the wall",
               base};
    s.scene.ambient = 20;
    s.scene.texture_contrast = 0.4;
    s.scene.laser_peak = 140;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 31;
    s.scene.backscatter = 8;
    s.scene.attenuation_per_m = 0.2;
    s.scene.snow_per_frame = 300;
    s.scene.snow_size_px = 1.2;
    s.scene.snow_brightness = 1.5;
    out.push_back(s);
  }
  for (int level = 1; level <= 3; ++level) {
    Scenario s{"turbid-" + std::to_string(level),
               "turbid water, level " + std::to_string(level) +
                   " of 3: attenuation, backscatter, forward scatter and veiling light",
               base};
    s.scene.ambient = 30;
    s.scene.texture_contrast = 0.4;
    s.scene.laser_peak = 120;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 37 + static_cast<std::uint64_t>(level);
    s.scene.attenuation_per_m = 0.3 * level;
    s.scene.backscatter = 12.0 * level;
    s.scene.forward_scatter = 0.15 * level;
    s.scene.scatter_halo_px = 6.0 * level;
    s.scene.veiling = 0.15 * level;
    out.push_back(s);
  }
  {
    Scenario s{"checkerboard",
               "daylight on a wall with a large checkerboard (6 cm squares): sharp edges of full "
               "contrast along and across the line",
               base};
    s.scene.ambient = 140;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 100;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 43;
    s.scene.checkerboard.columns = 11;
    s.scene.checkerboard.rows = 8;
    s.scene.checkerboard.square_m = 0.06;
    s.scene.checkerboard.dark_albedo = 0.08;
    out.push_back(s);
  }
  for (const bool mosaic : {false, true}) {
    Scenario s{mosaic ? "red-bayer" : "red-colour",
               std::string("a red laser on a colour camera") +
                   (mosaic ? " delivering a Bayer mosaic (RGGB)" : " (RGB)") +
                   " in daylight as bright as the laser; channel red - (green + blue) / 2",
               base};
    s.scene.ambient = 150;
    s.scene.texture_contrast = 0.6;
    s.scene.laser_peak = 110;
    s.scene.noise_sigma = 2.0;
    s.scene.seed = 47;
    s.scene.colour = mosaic ? hal::SimColour::kBayerRggb : hal::SimColour::kRgb;
    s.scene.laser_rgb = {1.0, 0.08, 0.03};
    s.channel = hal::parse_laser_channel("red - (green + blue) / 2");
    out.push_back(s);
  }
  {
    Scenario s{"beside",
               "as clean, the laser beside the camera (to its left): the line runs down the image",
               base};
    s.scene.ambient = 40;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 180;
    s.scene.noise_sigma = 1.5;
    s.scene.seed = 11;
    s.scene.calibration.laser.side = hal::LaserSide::kLeft;
    s.scene.tilt_x_deg = 8.0;  // the surface turned across the line, as tilt_y is for the others
    s.scene.tilt_y_deg = 0.0;
    s.scene.scan_pan = true;  // the unit sweeps across the line
    out.push_back(s);
  }
  {
    Scenario s{"oblique", "as clean, the laser turned 30 degrees about the optical axis", base};
    s.scene.ambient = 40;
    s.scene.texture_contrast = 0.5;
    s.scene.laser_peak = 180;
    s.scene.noise_sigma = 1.5;
    s.scene.seed = 13;
    // The paper's sheet (projector 0.25 m above, 80 degrees) turned by 30 degrees.
    const double t = std::tan(10.0 * std::numbers::pi / 180.0);
    const double c30 = std::cos(std::numbers::pi / 6), s30 = std::sin(std::numbers::pi / 6);
    s.scene.calibration.laser.plane = std::array<double, 4>{-s30, c30, -t, 0.25};
    out.push_back(s);
  }
  return out;
}

hal::SimLineFamily line_family(const pipeline::SearchAxes& axes) {
  hal::SimLineFamily lines;
  lines.origin = axes.origin;
  lines.line_step = axes.line_step;
  lines.along = axes.along;
  lines.count = axes.lines;
  return lines;
}

Score evaluate(const Scenario& scenario, const std::string& detector_name,
               pipeline::DetectorOptions options, double tolerance_px,
               const std::function<void(const ScoredFrame&)>& on_frame) {
  hal::SimScene scene(scenario.scene);
  const hal::FrameFormat format = scene.format();
  options.geometry = daemon::scanner_geometry(scenario.scene.calibration);
  auto detector = pipeline::make_detector(detector_name, options);
  if (!detector) throw std::invalid_argument("unknown detector " + detector_name);
  detector->reset(format.width, format.height);
  pipeline::Profile profile(detector->max_points(format.width, format.height));
  std::vector<std::uint8_t> pixels(format.bytes());
  hal::SimGroundTruth truth;
  // A colour scene is rendered as the camera's buffer and delivered as the laser's channel, as a
  // colour camera backend does.
  const bool colour = scenario.scene.colour != hal::SimColour::kMono;
  std::vector<std::uint8_t> raw(colour ? scene.raw_bytes() : 0);
  const hal::PixelConverter converter =
      colour
          ? hal::PixelConverter(scene.raw_format(), format.width, format.height, scenario.channel)
          : hal::PixelConverter();

  Score score;
  std::vector<double> best;
  for (int i = 0; i < scenario.frames; ++i) {
    const auto sequence = static_cast<std::uint64_t>(scenario.first_frame + i);
    const bool laser_on = !scenario.alternate || sequence % 2 == 0;
    if (colour) {
      scene.render(sequence, laser_on, raw);
      converter.convert(raw.data(), raw.size() / static_cast<std::size_t>(format.height),
                        pixels.data(), static_cast<std::size_t>(format.stride));
    } else {
      scene.render(sequence, laser_on, pixels);
    }
    const pipeline::ImageView view{pixels.data(), format.width, format.height, format.stride};
    detector->detect(view, {sequence, laser_on}, profile);
    if (i == 0) continue;  // warm-up
    // The truth along the lines the detector searched.
    scene.ground_truth(sequence, laser_on, line_family(profile.axes()), truth);
    ++score.frames;

    const auto lines = truth.position.size();
    best.assign(lines, std::numeric_limits<double>::infinity());
    for (const pipeline::ProfilePoint& p : profile.points()) {
      if (!p.valid) continue;
      ++score.points;
      if (p.u < 0 || static_cast<std::size_t>(p.u) >= lines) continue;
      const float position = truth.position[static_cast<std::size_t>(p.u)];
      if (std::isnan(position)) continue;
      const double error = p.v - position;
      if (std::abs(error) <= tolerance_px) ++score.correct_points;
      double& b = best[static_cast<std::size_t>(p.u)];
      if (std::abs(error) < std::abs(b)) b = error;
    }
    for (std::size_t k = 0; k < lines; ++k) {
      if (std::isnan(truth.position[k])) continue;
      ++score.truth_columns;
      const double error = best[k];
      if (!(std::abs(error) <= tolerance_px)) continue;
      ++score.found_columns;
      score.sum_error += error;
      score.sum_squared_error += error * error;
      score.max_error = std::max(score.max_error, std::abs(error));
    }
    if (on_frame) on_frame({i, &pixels, format.width, format.height, &truth, &profile});
  }
  return score;
}

bool write_overlay(const std::string& path, const ScoredFrame& frame, double tolerance_px) {
  const cv::Mat grey(frame.height, frame.width, CV_8UC1,
                     const_cast<std::uint8_t*>(frame.pixels->data()));
  cv::Mat colour;
  cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
  auto paint = [&](double x, double y, const cv::Vec3b& bgr) {
    const auto u = static_cast<int>(std::lround(x)), v = static_cast<int>(std::lround(y));
    if (u >= 0 && u < frame.width && v >= 0 && v < frame.height) colour.at<cv::Vec3b>(v, u) = bgr;
  };
  // The truth 6 px before the line along its epipolar lines (above a line across the image).
  const hal::SimLineFamily& lines = frame.truth->lines;
  for (std::size_t k = 0; k < frame.truth->position.size(); ++k) {
    const float position = frame.truth->position[k];
    if (std::isnan(position)) continue;
    const auto [x, y] = lines.to_image(static_cast<double>(k), position - 6.0);
    paint(x, y, {255, 128, 0});
  }
  // Rejected candidates first (dim yellow), valid points over them: green where within the
  // tolerance of the truth, red where not.
  for (const bool valid : {false, true}) {
    for (const pipeline::ProfilePoint& p : frame.profile->points()) {
      if (p.valid != valid) continue;
      const bool on_line = p.u >= 0 && static_cast<std::size_t>(p.u) < frame.truth->position.size();
      const float position = on_line ? frame.truth->position[static_cast<std::size_t>(p.u)]
                                     : std::numeric_limits<float>::quiet_NaN();
      const bool correct = !std::isnan(position) && std::abs(p.v - position) <= tolerance_px;
      const auto [x, y] = frame.profile->image_point(p);
      paint(x, y,
            !valid    ? cv::Vec3b{0, 140, 140}
            : correct ? cv::Vec3b{0, 255, 0}
                      : cv::Vec3b{0, 0, 255});
    }
  }
  return cv::imwrite(path, colour);
}

}  // namespace laserline::tools
