// laserline-calibrate: the laser plane (and, unless given, the camera intrinsics) from views of
// a checkerboard with the laser line across it; writes the calibration file laserlined,
// laserline-extract and laserline-evaluate read.
#include <cstdio>
#include <cstdlib>
#include <opencv2/core/utils/logger.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "hal/calibration.hpp"
#include "hal/laser_channel.hpp"
#include "tools/cli.hpp"
#include "tools/laser_plane_calibration.hpp"

namespace {

using laserline::tools::PlaneCalibrationError;

constexpr const char* kUsage =
    "usage: laserline-calibrate --board COLSxROWS --square-m S [--calib FILE]\n"
    "                           [--laser-off INPUT]... [options] --output FILE INPUT...\n"
    "  --board COLSxROWS     inner corners of the checkerboard across and down, e.g. 9x6\n"
    "                        (a board of 10x7 squares); the numbers must differ\n"
    "  --square-m S          side of one square in metres (measure the printed board)\n"
    "  --calib FILE          use the camera intrinsics of this calibration file instead of\n"
    "                        estimating them; its laser section is the nominal mount\n"
    "  --laser-off INPUT     the same board poses with the laser off, one image per laser-on\n"
    "                        image, in the same order (repeatable; files or folders). The\n"
    "                        corners are then found without the line over them and the line in\n"
    "                        the difference on - off. Strongly recommended.\n"
    "  --distortion-terms N  when estimating intrinsics: 0 none, 2 k1 k2, 4 k1 k2 p1 p2,\n"
    "                        5 k1 k2 p1 p2 k3 (default 5)\n"
    "  --channel CHANNEL     the laser's light in colour images: red, green (default), blue,\n"
    "                        grey, or a weighted sum such as 'red - (green + blue) / 2'. The\n"
    "                        board is searched in luma. Mono images are taken as they are.\n"
    "  --detector NAME       laser detector on each view (default fir)\n"
    "  --saturation-level N  grey level from which the line's core counts as clipped (its\n"
    "                        centre is then the middle of the run; default 255); lower it\n"
    "                        for colour or compressed images, whose clipped cores are noisy\n"
    "  --baseline-m D --angle-deg B --sheet-width-m W --laser-side SIDE\n"
    "                        the nominal mount (design values; default: --calib's laser\n"
    "                        section, else 0.25 m, 80 deg, 0.003 m, above): where the detector\n"
    "                        looks for the line. SIDE: above, below, left or right of the\n"
    "                        camera (left and right: the line runs down the image).\n"
    "                        The sheet width written is measured on the views (the line's\n"
    "                        width at half maximum times its depth over f) unless\n"
    "                        --sheet-width-m is given.\n"
    "  --output FILE         the calibration file to write (camera + laser with `plane`)\n"
    "  INPUT                 laser-on images, files or folders (sorted by name), one per pose\n"
    "\n"
    "Take each pose with the camera and board still: the laser on, then off. Use at least 2\n"
    "poses with the board tilted differently (6-10 recommended: near and far, tilted left,\n"
    "right, up and down), the whole board in view and the laser line across it. Estimating the\n"
    "intrinsics needs the tilts; with --calib, 2 tilted poses at different distances suffice.\n"
    "A view without the board or without the line on it is reported and left out.\n"
    "Exit status: 0 written, 1 the views do not give a calibration, 2 bad arguments.\n";

[[noreturn]] void usage_error(const std::string& message) {
  laserline::cli::usage_error("laserline-calibrate", message);
}

double parse_number(const std::string& option, const char* text, double min, double max) {
  char* end = nullptr;
  const double value = std::strtod(text, &end);
  if (end == text || *end != '\0' || !(value >= min && value <= max)) {
    usage_error(option + ": expected a number between " + std::to_string(min) + " and " +
                std::to_string(max) + ", got '" + text + "'");
  }
  return value;
}

void print_report(const laserline::tools::PlaneCalibrationResult& r, bool width_given) {
  const auto& c = r.calibration.camera;
  std::printf("views:\n");
  std::printf("  %-40s %8s %8s %8s %7s %7s %7s %8s  %s\n", "view", "corn.px", "dist.m", "tilt.deg",
              "cand.", "line", "inl.", "rms.mm", "corners from / left out");
  int used = 0;
  for (const auto& v : r.views) {
    used += v.skipped.empty() ? 1 : 0;
    const std::string status = v.skipped.empty() ? v.corners_from : "left out: " + v.skipped;
    if (!v.board) {
      std::printf("  %-40s %8s %8s %8s %7s %7s %7s %8s  %s\n", v.name.c_str(), "-", "-", "-", "-",
                  "-", "-", "-", status.c_str());
      continue;
    }
    std::printf("  %-40s %8.3f %8.3f %8.2f %7d %7d %7d %8.3f  %s\n", v.name.c_str(),
                v.corner_rms_px, v.distance_m, v.tilt_deg, v.laser_candidates, v.laser_points,
                v.plane_inliers, v.plane_rms_mm, status.c_str());
  }
  std::printf("  %d of %zu views give the plane\n", used, r.views.size());
  if (r.intrinsics_estimated) {
    std::printf("camera (estimated, calibrateCamera RMS %.3f px):\n", r.camera_rms_px);
  } else {
    std::printf("camera (given):\n");
  }
  std::printf("  %dx%d fx %.3f fy %.3f cx %.3f cy %.3f distortion [%.6g %.6g %.6g %.6g %.6g]\n",
              c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.distortion[0], c.distortion[1],
              c.distortion[2], c.distortion[3], c.distortion[4]);
  std::printf(
      "  board corners reprojected: RMS %.3f px; they reach %.0f%% of the way to the "
      "image's corners\n",
      r.corner_rms_px, 100.0 * r.corner_coverage);
  if (r.intrinsics_estimated && r.corner_coverage < 0.8) {
    std::printf(
        "  warning: the distortion beyond %.0f%% is extrapolated; views with the board "
        "near the image's corners make it sure\n",
        100.0 * r.corner_coverage);
  }
  const auto p = r.calibration.laser.plane_coefficients();
  std::printf("laser plane: a*X + b*Y + c*Z + e = 0 (camera frame, metres, unit normal)\n");
  std::printf("  plane [%.9f, %.9f, %.9f, %.9f]\n", p[0], p[1], p[2], p[3]);
  std::printf("  distance from the camera centre %.2f mm, normal %.3f deg from the y axis\n",
              1000.0 * p[3], r.normal_angle_to_y_deg);
  std::printf("  as baseline and angle: %.2f mm, %.3f deg, the projector %s the camera%s\n",
              1000.0 * r.calibration.laser.baseline_m, r.calibration.laser.angle_deg,
              laserline::hal::to_string(r.calibration.laser.side),
              r.fits_baseline_model ? "" : " (clamped: the plane does not fit that model)");
  if (r.sheet_width_measured) {
    std::printf("  sheet width %.3f mm (the line's width at half maximum, median of %d points)\n",
                1000.0 * r.calibration.laser.sheet_width_m, r.width_points);
  } else if (width_given) {
    std::printf("  sheet width %.3f mm as given\n", 1000.0 * r.calibration.laser.sheet_width_m);
  } else {
    std::printf(
        "  sheet width %.3f mm, the nominal one: only %d of the %d points gave a width (clipped "
        "or blurred into their surroundings)\n",
        1000.0 * r.calibration.laser.sheet_width_m, r.width_points, r.inliers);
  }
  std::printf(
      "  the line was seen at depths %.3f to %.3f m: detector.frontend.min_depth_m and "
      "max_depth_m must cover the working range\n",
      r.depth_min_m, r.depth_max_m);
  std::printf("residuals over %d of %d laser points (views' lines):\n", r.inliers, r.points);
  std::printf("  distance to the plane: RMS %.3f mm, max %.3f mm\n", r.plane_rms_mm,
              r.plane_max_mm);
  std::printf("  in the image:          RMS %.3f px, max %.3f px\n", r.plane_rms_px,
              r.plane_max_px);
}

int run_calibrate(int argc, char** argv) {
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  laserline::tools::PlaneCalibrationOptions options;
  std::string calib_path, output;
  std::vector<std::string> inputs, off_inputs;
  std::optional<double> baseline, angle, sheet_width;
  laserline::hal::LaserSide side = laserline::hal::LaserSide::kAbove;
  bool side_given = false;
  bool board_given = false, square_given = false;
  laserline::cli::Arguments args(argc, argv, "laserline-calibrate", kUsage,
                                 {{"board", true},
                                  {"square-m", true},
                                  {"calib", true},
                                  {"laser-off", true},
                                  {"distortion-terms", true},
                                  {"detector", true},
                                  {"saturation-level", true},
                                  {"channel", true},
                                  {"laser-side", true},
                                  {"baseline-m", true},
                                  {"angle-deg", true},
                                  {"sheet-width-m", true},
                                  {"output", true}});
  while (args.next()) {
    const std::string& arg = args.name();
    auto value = [&]() -> const char* { return args.value().c_str(); };
    if (arg == "--board") {
      const std::string text = value();
      int cols = 0, rows = 0;
      char x = 0, extra = 0;
      if (std::sscanf(text.c_str(), "%d%c%d%c", &cols, &x, &rows, &extra) != 3 ||
          (x != 'x' && x != 'X') || cols < 2 || rows < 2 || cols > 100 || rows > 100) {
        usage_error("--board: expected COLSxROWS inner corners (2..100 each), e.g. 9x6, got '" +
                    text + "'");
      }
      options.board_columns = cols;
      options.board_rows = rows;
      board_given = true;
    } else if (arg == "--square-m") {
      options.square_m = parse_number(arg, value(), 1e-4, 10.0);
      square_given = true;
    } else if (arg == "--calib") {
      calib_path = value();
    } else if (arg == "--laser-off") {
      off_inputs.push_back(value());
    } else if (arg == "--distortion-terms") {
      options.distortion_terms = static_cast<int>(parse_number(arg, value(), 0, 5));
      if (options.distortion_terms != 0 && options.distortion_terms != 2 &&
          options.distortion_terms != 4 && options.distortion_terms != 5) {
        usage_error("--distortion-terms: expected 0, 2, 4 or 5");
      }
    } else if (arg == "--detector") {
      options.detector = value();
    } else if (arg == "--saturation-level") {
      options.frontend.saturation_level = static_cast<int>(parse_number(arg, value(), 1, 255));
    } else if (arg == "--channel") {
      try {
        options.channel = laserline::hal::parse_laser_channel(value());
      } catch (const std::invalid_argument& e) {
        usage_error(std::string("--channel: ") + e.what());
      }
    } else if (arg == "--laser-side") {
      const std::string text = value();
      side_given = false;
      for (auto s : {laserline::hal::LaserSide::kAbove, laserline::hal::LaserSide::kBelow,
                     laserline::hal::LaserSide::kLeft, laserline::hal::LaserSide::kRight}) {
        if (text == laserline::hal::to_string(s)) {
          side = s;
          side_given = true;
        }
      }
      if (!side_given) {
        usage_error("--laser-side: expected above, below, left or right, got '" + text + "'");
      }
    } else if (arg == "--baseline-m") {
      baseline = parse_number(arg, value(), 1e-3, 10.0);
    } else if (arg == "--angle-deg") {
      angle = parse_number(arg, value(), 1.0, 179.0);
    } else if (arg == "--sheet-width-m") {
      sheet_width = parse_number(arg, value(), 1e-5, 0.1);
    } else if (arg == "--output") {
      output = value();
    } else {
      inputs.push_back(args.value());
    }
  }
  if (!board_given) usage_error("--board is required");
  if (!square_given) usage_error("--square-m is required");
  if (output.empty()) usage_error("--output is required");
  if (inputs.empty()) usage_error("no input images");

  try {
    if (!calib_path.empty()) {
      // Its laser section is optional here: only the prior of what is being calibrated.
      const laserline::hal::Calibration given = laserline::hal::load_calibration_file(
          calib_path, laserline::hal::CalibrationParts::kCamera);
      options.intrinsics = given.camera;
      options.laser_prior = given.laser;
      options.laser_prior.plane.reset();  // what is being calibrated; d and beta stay the prior
    }
  } catch (const laserline::hal::ConfigError& e) {
    std::fprintf(stderr, "laserline-calibrate: %s\n", e.what());
    return 2;
  }
  if (baseline) options.laser_prior.baseline_m = *baseline;
  if (angle) options.laser_prior.angle_deg = *angle;
  if (sheet_width) {
    options.laser_prior.sheet_width_m = *sheet_width;
    options.measure_sheet_width = false;
  }
  if (side_given) options.laser_prior.side = side;
  options.on_skip = [](const std::string& message) {
    std::fprintf(stderr, "laserline-calibrate: left out %s\n", message.c_str());
  };

  try {
    const std::vector<std::string> on_files = laserline::tools::expand_image_inputs(inputs);
    std::vector<std::string> off_files;
    if (!off_inputs.empty()) {
      off_files = laserline::tools::expand_image_inputs(off_inputs);
      if (off_files.size() != on_files.size()) {
        throw PlaneCalibrationError("--laser-off gives " + std::to_string(off_files.size()) +
                                    " images for " + std::to_string(on_files.size()) +
                                    " laser-on images: need one per pose, in the same order");
      }
    }
    std::vector<laserline::tools::CalibrationView> views;
    for (std::size_t i = 0; i < on_files.size(); ++i) {
      laserline::tools::CalibrationView v;
      v.name = on_files[i];
      v.laser_on = laserline::tools::load_image(on_files[i], options.channel);
      if (!off_files.empty()) {
        v.laser_off = laserline::tools::load_image(off_files[i], options.channel);
      }
      views.push_back(std::move(v));
    }
    const auto result = laserline::tools::calibrate_laser_plane(views, options);
    print_report(result, sheet_width.has_value());
    std::string provenance = std::to_string(views.size()) + " views, board " +
                             std::to_string(options.board_columns) + "x" +
                             std::to_string(options.board_rows) + " inner corners, square " +
                             std::to_string(options.square_m) + " m";
    if (!calib_path.empty()) provenance += ", intrinsics from " + calib_path;
    laserline::tools::write_calibration_file(output, result, provenance);
    std::printf("written: %s\n", output.c_str());
  } catch (const PlaneCalibrationError& e) {
    std::fprintf(stderr, "laserline-calibrate: %s\n", e.what());
    return 1;
  } catch (const cv::Exception& e) {
    std::fprintf(stderr, "laserline-calibrate: OpenCV: %s\n", e.err.c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_calibrate);
}
