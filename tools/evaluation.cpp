// The simulator's scenarios, their scoring against its ground truth, the turbidity sweep (the
// paper's Fig. 7) and overlays: what laserline-evaluate and the scenario tests share.
// Over 600 lines: the scenarios' table alone is about 300 lines of data.
#include "tools/evaluation.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
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
    s.scene.calibration.laser.plane = Eigen::Vector4d{-s30, c30, -t, 0.25};
    out.push_back(s);
  }
  // Scenes that change one thing of an earlier one.
  const auto like = [&out](const std::string& name) {
    return *std::find_if(out.begin(), out.end(), [&](const Scenario& s) { return s.name == name; });
  };
  for (const char* from : {"clean", "ambient"}) {
    Scenario s = like(from);
    const bool daylight = s.name == "ambient";
    s.name = daylight ? "fan-daylight" : "fan";
    s.description = std::string("as ") + from +
                    ", the laser's fan (24 degrees) lights the middle half of the image only: the "
                    "wall beyond the line's ends shows its texture alone";
    s.scene.seed = 53;
    s.scene.laser_fan_deg = 24.0;
    out.push_back(s);
  }
  {
    Scenario s = like("ambient");
    s.name = "thin-sheet";
    s.description =
        "as ambient, a sheet 0.4 mm thick (or 1.5 mm at 4.5 m): its projection is half a pixel "
        "wide, the line in the image wider (the pixels and the lens)";
    s.scene.seed = 59;
    s.scene.calibration.laser.sheet_width_m = 0.0004;
    out.push_back(s);
  }
  {
    Scenario s = like("clipped");
    s.name = "bloom";
    s.description =
        "as clipped, through a soft lens (a blur of 6 px): the line, a saturated core in a "
        "glow, is 6.5 times as wide as the sheet predicts";
    s.scene.seed = 61;
    s.scene.blur_px = 6.0;
    out.push_back(s);
  }
  {
    Scenario s = like("pier");
    s.name = "pier-sunlit";
    s.description =
        "as pier, in bright sun on fine growth (features from 3 mm): the line at a third of the "
        "light, more texture ridges along each column brighter than the line than along pier";
    s.scene.seed = 67;
    s.scene.ambient = 130;
    s.scene.texture_contrast = 0.8;
    s.scene.texture_scale_m = 0.003;
    s.scene.laser_peak = 50;
    s.scene.marks_per_m2 = 10;
    s.scene.marks_albedo = 1.8;
    out.push_back(s);
  }
  {
    Scenario s = like("caustics");
    s.name = "caustics-noon";
    s.description =
        "as caustics, at noon in shallower water: a denser network of caustics five times the "
        "ambient light, drifting across a fainter line";
    s.scene.seed = 71;
    s.scene.caustic_peak = 5.0;
    s.scene.caustic_scale_m = 0.12;
    s.scene.laser_peak = 80;
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
      if (std::abs(error) <= tolerance_px) {
        ++score.correct_points;
        score.sum_snr_db += p.snr_db;
      }
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

Scenario turbidity_scenario(double level, int width, int height) {
  Scenario s;
  for (const Scenario& c : standard_scenarios(width, height))
    if (c.name == "clean") s = c;
  s.name = "turbidity";
  char description[96];
  std::snprintf(description, sizeof description, "a tank, the wall 1.4 m away, %.1f FTU", level);
  s.description = description;
  s.scene.distance_m = 1.4;
  s.scene.ambient = 20;
  s.scene.texture_contrast = 0.3;
  s.scene.laser_peak = 150;
  s.scene.noise_sigma = 2.0;
  s.scene.seed = 53;
  s.scene.attenuation_per_m = 0.15 * level;
  s.scene.backscatter = 6.0 * level;
  s.scene.forward_scatter = std::min(0.6, 0.06 * level);
  s.scene.scatter_halo_px = 2.0 * level;
  s.scene.veiling = std::min(0.6, 0.06 * level);
  return s;
}

TurbiditySweep sweep_turbidity(const std::vector<double>& levels,
                               const std::vector<double>& passband_ratios,
                               const std::vector<std::string>& detectors, int frames,
                               double tolerance_px) {
  TurbiditySweep sweep;
  sweep.levels = levels;
  sweep.passband_ratios = passband_ratios;
  sweep.detectors = detectors;
  for (const double ratio : passband_ratios) {
    std::vector<double> snr;
    for (const double level : levels) {
      Scenario s = turbidity_scenario(level);
      s.frames = frames;
      pipeline::DetectorOptions o;
      o.frontend.passband_ratio = ratio;
      snr.push_back(evaluate(s, "fir", o, tolerance_px).mean_snr_db());
    }
    sweep.snr_db.push_back(snr);
  }
  for (const std::string& name : detectors) {
    std::vector<double> recall;
    double loses = std::numeric_limits<double>::quiet_NaN();
    for (const double level : levels) {
      Scenario s = turbidity_scenario(level);
      s.frames = frames;
      recall.push_back(evaluate(s, name, {}, tolerance_px).recall());
      if (std::isnan(loses) && recall.back() < 0.5) loses = level;
    }
    sweep.recall.push_back(recall);
    sweep.loses_line_at.push_back(loses);
  }
  return sweep;
}

bool write_turbidity_csv(const std::string& csv_path, const TurbiditySweep& sweep) {
  std::FILE* f = std::fopen(csv_path.c_str(), "w");
  if (f == nullptr) return false;
  std::fprintf(f, "turbidity_ftu");
  for (const double ratio : sweep.passband_ratios)
    std::fprintf(f, ",snr_db_passband_%g", ratio);
  for (const std::string& d : sweep.detectors)
    std::fprintf(f, ",recall_%s", d.c_str());
  std::fprintf(f, "\n");
  for (std::size_t i = 0; i < sweep.levels.size(); ++i) {
    std::fprintf(f, "%g", sweep.levels[i]);
    for (const auto& snr : sweep.snr_db)
      std::fprintf(f, ",%.2f", snr[i]);
    for (const auto& recall : sweep.recall)
      std::fprintf(f, ",%.4f", recall[i]);
    std::fprintf(f, "\n");
  }
  return std::fclose(f) == 0;
}

namespace {

// A line chart on `image` inside `area`: x from the levels, y from y_lo to y_hi.
struct Chart {
  cv::Mat& image;
  cv::Rect area;
  double x_lo, x_hi, y_lo, y_hi;
  bool legend_below = false;  // the legend in the lower left corner, else the upper right

  cv::Point at(double x, double y) const {
    const double fx = (x - x_lo) / (x_hi - x_lo), fy = (y - y_lo) / (y_hi - y_lo);
    return {area.x + static_cast<int>(std::lround(fx * area.width)),
            area.y + area.height -
                static_cast<int>(std::lround(std::clamp(fy, 0.0, 1.0) * area.height))};
  }
  void axes(const std::string& title, const std::string& x_label, double y_step) const {
    const cv::Scalar ink(0, 0, 0), grid(220, 220, 220);
    for (double y = y_lo; y <= y_hi + 1e-9; y += y_step) {
      cv::line(image, at(x_lo, y), at(x_hi, y), grid, 1);
      char text[16];
      std::snprintf(text, sizeof text, "%g", y);
      cv::putText(image, text, at(x_lo, y) + cv::Point(-40, 5), cv::FONT_HERSHEY_SIMPLEX, 0.4, ink,
                  1, cv::LINE_AA);
    }
    for (double x = x_lo; x <= x_hi + 1e-9; x += x_hi - x_lo > 10 ? 2.0 : 1.0) {
      char text[16];
      std::snprintf(text, sizeof text, "%g", x);
      cv::putText(image, text, at(x, y_lo) + cv::Point(-4, 18), cv::FONT_HERSHEY_SIMPLEX, 0.4, ink,
                  1, cv::LINE_AA);
    }
    cv::rectangle(image, area, ink, 1);
    cv::putText(image, title, {area.x, area.y - 12}, cv::FONT_HERSHEY_SIMPLEX, 0.5, ink, 1,
                cv::LINE_AA);
    cv::putText(image, x_label, {area.x + area.width / 2 - 60, area.y + area.height + 38},
                cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);
  }
  void curve(const std::vector<double>& xs, const std::vector<double>& ys, const cv::Scalar& colour,
             const std::string& label, int legend_row) const {
    for (std::size_t i = 0; i + 1 < xs.size(); ++i)
      cv::line(image, at(xs[i], ys[i]), at(xs[i + 1], ys[i + 1]), colour, 2, cv::LINE_AA);
    for (std::size_t i = 0; i < xs.size(); ++i)
      cv::circle(image, at(xs[i], ys[i]), 3, colour, cv::FILLED, cv::LINE_AA);
    const cv::Point legend =
        legend_below ? cv::Point(area.x + 12, area.y + area.height - 90 + 18 * legend_row)
                     : cv::Point(area.x + area.width - 170, area.y + 18 + 18 * legend_row);
    cv::line(image, legend, legend + cv::Point(20, 0), colour, 2, cv::LINE_AA);
    cv::putText(image, label, legend + cv::Point(26, 4), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
};

}  // namespace

bool write_turbidity_plot(const std::string& png_path, const TurbiditySweep& sweep) {
  if (sweep.levels.size() < 2) return false;
  cv::Mat image(520, 1100, CV_8UC3, cv::Scalar(255, 255, 255));
  const std::array<cv::Scalar, 6> colours{cv::Scalar(180, 90, 20), cv::Scalar(40, 140, 40),
                                          cv::Scalar(20, 20, 200), cv::Scalar(160, 40, 160),
                                          cv::Scalar(0, 140, 200), cv::Scalar(90, 90, 90)};
  const double x_lo = sweep.levels.front(), x_hi = sweep.levels.back();
  double snr_hi = 10;
  for (const auto& snr : sweep.snr_db)
    for (double v : snr)
      snr_hi = std::max(snr_hi, std::ceil(v / 5.0) * 5.0);
  const Chart snr{image, cv::Rect(70, 50, 430, 380), x_lo, x_hi, 0.0, snr_hi};
  snr.axes("SNR of the detected line (fir), dB", "turbidity, FTU", 5.0);
  // The paper's limit: below 3 dB no clear detection.
  cv::line(image, snr.at(x_lo, 3.0), snr.at(x_hi, 3.0), cv::Scalar(0, 0, 0), 1, cv::LINE_4);
  cv::putText(image, "3 dB", snr.at(x_lo, 3.0) + cv::Point(4, -4), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  for (std::size_t k = 0; k < sweep.snr_db.size(); ++k) {
    char label[40];
    std::snprintf(label, sizeof label, "passband ratio %g", sweep.passband_ratios[k]);
    snr.curve(sweep.levels, sweep.snr_db[k], colours[k % colours.size()], label,
              static_cast<int>(k));
  }
  const Chart recall{image, cv::Rect(630, 50, 430, 380), x_lo, x_hi, 0.0, 100.0, true};
  recall.axes("line found (recall), %", "turbidity, FTU", 20.0);
  for (std::size_t k = 0; k < sweep.recall.size(); ++k) {
    std::vector<double> percent;
    for (double r : sweep.recall[k])
      percent.push_back(100.0 * r);
    std::string label = sweep.detectors[k];
    if (!std::isnan(sweep.loses_line_at[k])) {
      char at[32];
      std::snprintf(at, sizeof at, " (< 50%% at %g)", sweep.loses_line_at[k]);
      label += at;
    }
    recall.curve(sweep.levels, percent, colours[k % colours.size()], label, static_cast<int>(k));
  }
  return cv::imwrite(png_path, image);
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
