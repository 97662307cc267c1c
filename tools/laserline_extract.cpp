// laserline-extract: runs a laserline detector over recorded frames (image files, folders of
// images, videos, LCM logs of laserline.image_t) and writes the laser points to a CSV file, with
// an optional overlay PNG per frame, and optionally the 3-D points of all frames as one PLY point
// cloud (in the camera frame, or fused into the world frame with a pose log). Same calibration,
// configuration and detectors as laserlined.
//
// Single-threaded. Every frame's points are written and flushed before the next frame is read,
// so an interruption or a bad input never loses what was already extracted.
//
// This file: the command line, the checks of the calibration, configuration and outputs before
// the first frame, and the summary; the inputs are read in extract_inputs.cpp, each frame
// detected and written in extractor.cpp.
// Over 600 lines: one program's command line, its --help text (about 80 lines) among them.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "hal/calibration.hpp"
#include "hal/laser_channel.hpp"
#include "pipeline/detector.hpp"
#include "pipeline/options.hpp"
#include "tools/cli.hpp"
#include "tools/extract_inputs.hpp"
#include "tools/extractor.hpp"
#include "tools/point_cloud.hpp"

namespace {

namespace fs = std::filesystem;
using laserline::hal::ConfigError;
using laserline::tools::extract::CalibrationInUse;
using laserline::tools::extract::Extractor;
using laserline::tools::extract::InputKind;
using laserline::tools::extract::LogCalibration;
using laserline::tools::extract::Options;
using laserline::tools::extract::Region;

constexpr const char* kUsage =
    "usage: laserline-extract [--calib FILE [--override-log-calibration]] [--config FILE]\n"
    "                         --detector NAME [--threshold VALUE] [--depth-range MIN,MAX]\n"
    "                         [--channel NAME|EXPR] [--roi x,y,w,h] [--mask FILE]\n"
    "                         [--laser-pattern BITS] [--overlay-dir DIR] [--all-candidates]\n"
    "                         [--keep-sheet-width] [--bit-depth N]\n"
    "                         [--output points.csv] [--ply cloud.ply [--poses poses.csv]]\n"
    "                         INPUT...\n"
    "  --calib FILE       calibration (camera and laser); images must have its size. Without\n"
    "                     it, the calibration an LCM log carries (laserline.calibration_t, which\n"
    "                     laserlined publishes); with it, a log recorded with another calibration\n"
    "                     (its calibration_t or its profiles' calibration_id) is refused\n"
    "  --override-log-calibration  extract such a log with --calib all the same (a newer\n"
    "                     calibration of the same scanner)\n"
    "  --config FILE      laserlined configuration whose detector options are used\n"
    "                     (default: the built-in configuration)\n"
    "  --detector NAME    detector to run (see the list below)\n"
    "  --threshold VALUE  the detector's threshold in its own unit, instead of the\n"
    "                     configuration's: maxvalue a grey level 1..255 that a line's brightest\n"
    "                     pixel must reach (built-in 40); fir, background, backprojection an\n"
    "                     SNR in dB 0..60 (built-in 6)\n"
    "  --depth-range MIN,MAX  fir, background, backprojection search the line only where the\n"
    "                     laser sheet lies between these depths (metres, 0.01 to 1000). Default:\n"
    "                     with --config, its detector.frontend.min_depth_m and max_depth_m;\n"
    "                     without, every depth the frames see up to 100 baselines (the sheet's\n"
    "                     distance from the camera centre), said on stderr\n"
    "  --channel NAME|EXPR  the laser's light in colour frames: red, green (default), blue,\n"
    "                     grey, or a weighted sum such as \"red - (green + blue) / 2\" (also\n"
    "                     cancels white light); mono frames are taken as they are\n"
    "  --roi x,y,w,h      search only this rectangle (left column, top row, width, height in\n"
    "                     pixels; the filters still read the pixels around it), in place of\n"
    "                     the configuration's detector.roi\n"
    "  --mask FILE        keep only points on non-zero pixels of this image (the frames' size)\n"
    "  --laser-pattern BITS  the laser state of successive frames, 1 on, 0 off, repeated from\n"
    "                     the start of each sequence (folder, video, log, run of image files):\n"
    "                     10 for on/off alternation. Laser-off frames still reach the detector\n"
    "                     (background keeps them as the next frame's background) but give no\n"
    "                     points. LCM logs' own laser states (their profiles) take precedence.\n"
    "                     Not given (fir, background, backprojection): where the line comes\n"
    "                     and goes at every frame in the first 16 frames of the images or\n"
    "                     video, 10 or 01 (and it is said)\n"
    "  --overlay-dir DIR  write DIR/frame_NNNNNN.png per frame: the grey image the detector saw\n"
    "                     with its points (accepted green, rejected red)\n"
    "  --all-candidates   also write rejected candidates (valid = 0)\n"
    "  --keep-sheet-width  fir, background, backprojection size their filters for the line\n"
    "                     width the calibration predicts (laser.sheet_width_m); where the\n"
    "                     line in the first frames of the images and videos is over 1.5\n"
    "                     times as wide or under 2/3 as wide, they are sized for the width\n"
    "                     measured (and it is said). This keeps the calibration's width\n"
    "  --bit-depth N      16-bit frames hold N-bit samples (8 to 16): 0..2^N-1 is scaled onto\n"
    "                     the detectors' 0..255. Default: from the frames (see below)\n"
    "  --output FILE      CSV: frame,source,u,v,x,y,snr_db,segment,valid (source: the image\n"
    "                     file, or the video's frame or the log's event; u the epipolar line and\n"
    "                     v the position along it, x y the frame pixel: for a laser above or\n"
    "                     below the camera u = x the column, v = y the row; beside it, u = y\n"
    "                     the row, v = x the column); - for standard output\n"
    "  --ply FILE         the valid points of all frames as one point cloud: binary PLY,\n"
    "                     float x y z (metres) and scalar_snr (SNR in dB; CloudCompare shows\n"
    "                     it as the scalar field \"snr\"), for CloudCompare, MeshLab, PCL;\n"
    "                     in the camera frame unless --poses is given\n"
    "  --poses FILE       CSV timestamp,x,y,z,qw,qx,qy,qz (header line allowed): the pose of\n"
    "                     the camera in the world frame (X_world = R(q) X_camera + (x,y,z)),\n"
    "                     timestamps in seconds, increasing. Frames with a time (LCM logs:\n"
    "                     utime) get the pose interpolated at it (position linear, rotation\n"
    "                     slerp); frames without (images, videos) take the row of their frame\n"
    "                     number. The PLY is then in the world frame (float: keep the world\n"
    "                     origin near the scan, e.g. a local frame rather than UTM)\n"
    "  (at least one of --output and --ply)\n"
    "  INPUT              image files (in the order given), folders of images (in natural\n"
    "                     order: 2 before 10), videos (.avi .mp4 .mkv .mov ...), LCM logs of\n"
    "                     laserline.image_t messages (damaged records are skipped, reported\n"
    "                     with their byte offsets, and reading resumes at the next whole event;\n"
    "                     a damaged or cut-short log counts as a failed input: exit status 1)\n"
    "Colour frames: the green channel is used unless --channel. 16-bit frames are scaled to\n"
    "8 bit from the range their samples use: the fewest of 8, 10, 12, 14 or 16 bits that hold\n"
    "the first 16-bit frame of each sequence (a 12-bit camera's 0..4095: said on stderr), more\n"
    "where a later frame needs it; --bit-depth N fixes it (larger samples are taken as the top).\n"
    "Exit status: 0 all frames processed; 1 some input or frame failed (the others are\n"
    "still written); 2 bad arguments, configuration or calibration (nothing read); 3 frames\n"
    "were read but no point was accepted, or more than half of the accepted points had no 3-D\n"
    "point for --ply (the laser sheet of the calibration misses them); 3 before 1.\n";

[[noreturn]] void usage_error(const std::string& line) {
  laserline::cli::usage_error("laserline-extract", line);
}

[[noreturn]] void fatal(const std::string& line) {
  std::fprintf(stderr, "laserline-extract: %s\n", line.c_str());
  throw laserline::cli::Exit(2);
}

std::string detector_list() {
  std::string list;
  for (const auto& name : laserline::pipeline::detector_names())
    list += (list.empty() ? "" : ", ") + name;
  return list;
}

Options parse_arguments(int argc, char** argv) {
  Options o;
  laserline::cli::Arguments args(argc, argv, "laserline-extract",
                                 std::string(kUsage) + "detectors: " + detector_list() + "\n",
                                 {{"calib", true},
                                  {"config", true},
                                  {"detector", true},
                                  {"threshold", true},
                                  {"depth-range", true},
                                  {"channel", true},
                                  {"roi", true},
                                  {"mask", true},
                                  {"laser-pattern", true},
                                  {"overlay-dir", true},
                                  {"output", true},
                                  {"ply", true},
                                  {"poses", true},
                                  {"all-candidates", false},
                                  {"keep-sheet-width", false},
                                  {"bit-depth", true},
                                  {"override-log-calibration", false}});
  while (args.next()) {
    const std::string& arg = args.name();
    if (arg.empty()) {
      o.inputs.push_back(args.value());
      continue;
    }
    auto value = [&]() -> std::string { return args.value(); };
    if (arg == "--calib") {
      o.calib = value();
    } else if (arg == "--config") {
      o.config = value();
    } else if (arg == "--detector") {
      o.detector = value();
    } else if (arg == "--threshold") {
      o.threshold = value();
    } else if (arg == "--depth-range") {
      o.depth_range = value();
    } else if (arg == "--channel") {
      try {
        o.channel = laserline::hal::parse_laser_channel(value());
      } catch (const std::invalid_argument& e) {
        fatal(std::string("--") + e.what());  // the reason starts: channel "TEXT": ...
      }
    } else if (arg == "--roi") {
      o.roi = value();
    } else if (arg == "--mask") {
      o.mask = value();
    } else if (arg == "--laser-pattern") {
      o.laser_pattern = value();
      const std::string& bits = o.laser_pattern;
      if (bits.empty() || bits.size() > 1024 || bits.find_first_not_of("01") != std::string::npos) {
        fatal("--laser-pattern '" + bits +
              "': expected 1 to 1024 characters 0 (laser off) or 1 (laser on), e.g. 10 for "
              "on/off alternation");
      }
      if (bits.find('1') == std::string::npos) {
        fatal("--laser-pattern '" + bits + "': has no 1, so no frame would have the laser on");
      }
      o.laser_on_pattern.clear();
      for (char bit : bits)
        o.laser_on_pattern.push_back(bit == '1');
    } else if (arg == "--overlay-dir") {
      o.overlay_dir = value();
    } else if (arg == "--output") {
      o.output = value();
    } else if (arg == "--ply") {
      o.ply = value();
    } else if (arg == "--poses") {
      o.poses = value();
    } else if (arg == "--all-candidates") {
      o.all_candidates = true;
    } else if (arg == "--keep-sheet-width") {
      o.keep_sheet_width = true;
    } else if (arg == "--bit-depth") {
      const std::string text = value();
      if (text.empty() || text.size() > 2 ||
          text.find_first_not_of("0123456789") != std::string::npos || std::stoi(text) < 8 ||
          std::stoi(text) > 16) {
        fatal("--bit-depth '" + text +
              "': the bits of the camera's samples in 16-bit frames, a whole number from 8 to 16");
      }
      o.bit_depth = std::stoi(text);
    } else if (arg == "--override-log-calibration") {
      o.override_log_calibration = true;
    }
  }
  if (o.override_log_calibration && o.calib.empty()) {
    usage_error("--override-log-calibration goes with --calib");
  }
  if (o.detector.empty()) usage_error("--detector is required (one of: " + detector_list() + ")");
  if (o.output.empty() && o.ply.empty()) usage_error("--output or --ply is required");
  if (!o.poses.empty() && o.ply.empty()) usage_error("--poses needs --ply");
  if (o.inputs.empty()) usage_error("no INPUT given");
  return o;
}

// --threshold into the chosen detector's own option, in its own unit.
void apply_threshold(const Options& o, laserline::pipeline::DetectorOptions& detector_options) {
  if (o.threshold.empty()) return;
  const char* text = o.threshold.c_str();
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(text, &end);
  const bool number = errno == 0 && end != text && *end == '\0' && std::isfinite(value);
  if (o.detector == "maxvalue") {
    if (!number || value != std::floor(value) || value < 1 || value > 255) {
      fatal("--threshold " + o.threshold +
            ": the maxvalue detector's threshold is a grey level, a whole number from 1 to 255");
    }
    detector_options.maxvalue_threshold = static_cast<int>(value);
  } else {
    if (!number || value < 0 || value > 60) {
      fatal("--threshold " + o.threshold + ": the " + o.detector +
            " detector's threshold is an SNR in dB, a number from 0 to 60");
    }
    detector_options.frontend.snr_threshold_db = value;
  }
}

// The depths searched (fir, background, backprojection): --depth-range; else a --config's; else
// every depth the frames see, up to kMaxBaselines baselines: the built-in configuration's range is
// the vehicle's working distance, and someone else's scanner (a desk scanner, a turntable) may
// work at a tenth of it. Beyond some 100 baselines a pixel of the line is several percent of its
// depth, and toward the horizon the rows would be stretched for a line thinner than the blur.
// Returns the line that says so in the last case (said once the other arguments are checked).
std::string choose_depth_range(const Options& o, const laserline::hal::Calibration& calibration,
                               laserline::pipeline::FrontendOptions& frontend) {
  constexpr double kMaxBaselines = 100.0;
  const laserline::daemon::DepthsSeen seen = laserline::daemon::depths_seen(calibration);
  if (!o.depth_range.empty()) {
    double lo = 0, hi = 0;
    char tail = 0;
    if (std::sscanf(o.depth_range.c_str(), "%lf,%lf%c", &lo, &hi, &tail) != 2 ||
        !std::isfinite(lo) || !std::isfinite(hi) || lo < 0.01 || hi > 1000 || !(lo < hi)) {
      fatal("--depth-range '" + o.depth_range +
            "': expected MIN,MAX in metres, 0.01 <= MIN < MAX <= 1000, e.g. 0.2,1.5");
    }
    frontend.min_depth_m = lo;
    frontend.max_depth_m = hi;
    return {};
  }
  if (!o.config.empty() || !(seen.nearest > 0)) return {};  // (the check that follows says why)
  const Eigen::Vector4d plane = calibration.laser.plane_coefficients();
  const double baseline = std::abs(plane[3]) / plane.head<3>().norm();
  frontend.min_depth_m = std::clamp(seen.nearest, 0.01, 999.0);
  frontend.max_depth_m = std::clamp(std::min(seen.farthest, kMaxBaselines * baseline),
                                    frontend.min_depth_m * 1.01, 1000.0);
  char line[200];
  std::snprintf(line, sizeof line,
                "laserline-extract: searching the laser sheet at depths %.3g to %.3g m (what the "
                "frames see, up to %.0f baselines of %.3g m; --depth-range MIN,MAX to change)\n",
                frontend.min_depth_m, frontend.max_depth_m, kMaxBaselines, baseline);
  return line;
}

// --roi and --mask, checked against the frames' size (the calibration's). --roi is also the
// region the detector searches (*searched), in place of the configuration's detector.roi.
Region region_of(const Options& o, int width, int height,
                 laserline::pipeline::DetectionRegion* searched) {
  Region region;
  const std::string frames = std::to_string(width) + "x" + std::to_string(height) +
                             " frames of the calibration " + o.calib;
  if (!o.roi.empty()) {
    int x = 0, y = 0, w = 0, h = 0;
    char tail = 0;
    if (std::sscanf(o.roi.c_str(), "%d,%d,%d,%d%c", &x, &y, &w, &h, &tail) != 4 || x < 0 || y < 0 ||
        w < 1 || h < 1) {
      fatal("--roi '" + o.roi +
            "': expected x,y,w,h: left column, top row (from 0), width and height (from 1) in "
            "pixels, e.g. 0,100,1280,600");
    }
    if (static_cast<long>(x) + w > width || static_cast<long>(y) + h > height) {
      fatal("--roi " + o.roi + ": reaches beyond the " + frames);
    }
    region.limit_to(cv::Rect(x, y, w, h));
    *searched = {x, y, w, h};
  }
  if (!o.mask.empty()) {
    cv::Mat image;
    try {
      image = cv::imread(o.mask, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception&) {
      image.release();
    }
    if (image.empty()) {
      fatal("--mask " + o.mask + ": " +
            (access(o.mask.c_str(), R_OK) != 0
                 ? std::string("cannot be read: ") + std::strerror(errno)
                 : std::string("not a readable image")));
    }
    if (image.cols != width || image.rows != height) {
      fatal("--mask " + o.mask + ": is " + std::to_string(image.cols) + "x" +
            std::to_string(image.rows) + " but must have the size of the " + frames);
    }
    // Any colour channel set marks a kept pixel (an alpha channel does not count).
    std::vector<cv::Mat> planes;
    cv::split(image, planes);
    const std::size_t colours = planes.size() >= 3 ? 3 : 1;  // grey or BGR, each maybe + alpha
    cv::Mat kept = planes[0] != 0;
    for (std::size_t c = 1; c < colours; ++c)
      kept |= planes[c] != 0;
    if (cv::countNonZero(kept) == 0) {
      fatal("--mask " + o.mask + ": no pixel is set (points are kept on non-zero pixels)");
    }
    region.limit_to(kept);
  }
  return region;
}

// The front end's filters are sized for the line width the calibration predicts (f l_w / Z, from
// laser.sheet_width_m); a line several times wider (blur, bloom, a clipped core) or narrower is
// answered weakly, and a guessed sheet width is common on someone else's images. The width is
// measured on the first frames of the images and videos; off by more than kWidthTolerance, the
// filters are sized for what was measured (measured again: a detection sized for a width far off
// finds the line poorly), and it is said. (Sized for the width the calibration predicts, the
// filters find the line best though the lens and the pixels widen it by a third or so; a line
// measured twice as wide as predicted loses a good part of its points.)
void fit_sheet_width(const Options& options, const laserline::hal::Calibration& calibration,
                     const Region& region, const std::vector<InputKind>& kinds,
                     const CalibrationInUse& in_use,
                     laserline::pipeline::DetectorOptions& detector_options) {
  constexpr std::int64_t kWidthFrames = 12;
  constexpr std::size_t kMinimumPoints = 200;
  constexpr double kWidthTolerance = 1.5;
  if (options.keep_sheet_width || !laserline::daemon::searches_depth_range(options.detector)) {
    return;
  }
  // Images, folders and videos: a log was recorded by laserlined with the calibration it carries,
  // and is read whole before its frames (its laser states), which a probe would repeat.
  std::vector<std::string> probed;
  std::vector<InputKind> probed_kinds;
  for (std::size_t i = 0; i < options.inputs.size(); ++i) {
    if (kinds[i] == InputKind::kLog) continue;
    probed.push_back(options.inputs[i]);
    probed_kinds.push_back(kinds[i]);
  }
  if (probed.empty()) return;
  const double stated = detector_options.geometry.sheet_width_m;
  std::size_t measured = 0;
  for (int pass = 0; pass < 3; ++pass) {
    laserline::tools::LineWidthMeter meter(detector_options.geometry,
                                           detector_options.frontend.saturation_level);
    Extractor probe(options, calibration,
                    laserline::pipeline::make_detector(options.detector, detector_options), region,
                    nullptr, nullptr, nullptr);
    probe.measure_width_only(meter, kWidthFrames);
    laserline::tools::extract::extract_inputs(probe, probed, probed_kinds, in_use);
    if (meter.measured() < kMinimumPoints) break;
    const double ratio = meter.ratio();
    if (ratio < kWidthTolerance && ratio > 1.0 / kWidthTolerance) break;
    detector_options.geometry.sheet_width_m *= ratio;
    measured = meter.measured();
  }
  if (measured == 0) return;
  const double used = detector_options.geometry.sheet_width_m;
  std::fprintf(stderr,
               "laserline-extract: the laser line in the first frames is %.2f times as wide as "
               "laser.sheet_width_m %.4g m of %s predicts (%zu points): extracting with %.4g m "
               "(set it in the calibration; --keep-sheet-width keeps %.4g)\n",
               used / stated, stated, options.calib.c_str(), measured, used, stated);
}

// A sequence recorded with the laser switched on and off every other frame (the classic on/off
// method), given without --laser-pattern: every laser-off frame would be searched as a laser-on
// one, and the texture it shows taken for the line. The first frames of the first sequence of
// images or video are searched with `fir`, each frame as laser-on; where the line's evidence
// (the SNR above the threshold summed over its points) goes up and down at every frame (all but
// one) and is three times as high in one half as in the other, the laser is taken to alternate,
// and it is said. A sequence whose line merely varies does not go up and down a dozen times in a
// row.
bool detect_laser_alternation(Options& options, const laserline::hal::Calibration& calibration,
                              const Region& region, const std::vector<InputKind>& kinds,
                              const CalibrationInUse& in_use,
                              const laserline::pipeline::DetectorOptions& detector_options) {
  constexpr std::int64_t kFrames = 16;
  constexpr std::size_t kFewest = 12;
  constexpr double kRatio = 3.0;
  // (Searched with fir, as the detectors that search the depth range are; maxvalue's frames are
  // not probed.)
  if (!options.laser_on_pattern.empty() ||
      !laserline::daemon::searches_depth_range(options.detector)) {
    return false;
  }
  std::vector<std::string> probed;
  std::vector<InputKind> probed_kinds;
  for (std::size_t i = 0; i < options.inputs.size(); ++i) {
    if (kinds[i] == InputKind::kLog) continue;  // a log says its frames' laser states
    probed.push_back(options.inputs[i]);
    probed_kinds.push_back(kinds[i]);
  }
  if (probed.empty()) return false;
  std::vector<Extractor::FrameEvidence> frames;
  Extractor probe(options, calibration, laserline::pipeline::make_detector("fir", detector_options),
                  region, nullptr, nullptr, nullptr);
  probe.measure_evidence_only(frames, kFrames, detector_options.frontend.snr_threshold_db);
  laserline::tools::extract::extract_inputs(probe, probed, probed_kinds, in_use);
  // The first sequence's frames, in an unbroken run from its start.
  std::vector<double> evidence;
  for (const Extractor::FrameEvidence& f : frames) {
    if (f.sequence != frames.front().sequence ||
        f.position != static_cast<std::int64_t>(evidence.size()))
      break;
    evidence.push_back(f.evidence);
  }
  if (evidence.size() < kFewest) return false;
  for (const int first_on : {0, 1}) {
    int against = 0;  // steps from one frame to the next that do not go the pattern's way
    std::vector<double> on, off;
    for (std::size_t i = 0; i < evidence.size(); ++i) {
      const bool laser_on = static_cast<int>(i % 2) == first_on;
      (laser_on ? on : off).push_back(evidence[i]);
      if (i + 1 < evidence.size() && (evidence[i] > evidence[i + 1]) != laser_on) ++against;
    }
    // (One step against it is allowed: a frame whose line left the view, or glinted.)
    const bool alternates = against <= 1;
    auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    const double on_median = median(on), off_median = median(off);
    if (!alternates || !(on_median > 0) || on_median < kRatio * off_median) continue;
    options.laser_pattern = first_on == 0 ? "10" : "01";
    options.laser_on_pattern = {first_on == 0, first_on == 1};
    std::fprintf(
        stderr,
        "laserline-extract: the line comes and goes at every frame in the first %zu frames "
        "of %s (its evidence %.0f against %.0f dB): the laser alternates, extracting "
        "with --laser-pattern %s (--laser-pattern 1 takes every frame as laser-on)\n",
        evidence.size(), probed.front().c_str(), on_median, off_median,
        options.laser_pattern.c_str());
    return true;
  }
  return false;
}

int run_extract(int argc, char** argv) {
  // OpenCV's own warnings (e.g. a failing decoder) would duplicate our one line per problem.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  Options options = parse_arguments(argc, argv);

  const auto names = laserline::pipeline::detector_names();
  if (std::find(names.begin(), names.end(), options.detector) == names.end()) {
    fatal("--detector: unknown detector '" + options.detector + "' (one of: " + detector_list() +
          ")");
  }
  std::vector<InputKind> kinds;
  for (const auto& input : options.inputs)
    kinds.push_back(laserline::tools::extract::kind_of(input));
  laserline::hal::Calibration calibration;
  CalibrationInUse in_use;
  in_use.accept_others = options.override_log_calibration;
  if (!options.calib.empty()) {
    try {
      calibration = laserline::hal::load_calibration_file(options.calib);
    } catch (const ConfigError& e) {
      fatal(e.what());
    }
    in_use.id = laserline::hal::calibration_id(calibration);
    in_use.name = options.calib;
  }
  // What the logs among the inputs were recorded with: before any output is written.
  std::optional<LogCalibration> from_log;
  for (std::size_t i = 0; i < options.inputs.size(); ++i) {
    if (kinds[i] != InputKind::kLog) continue;
    LogCalibration log = laserline::tools::extract::first_log_calibration(options.inputs[i]);
    if (log.where.empty()) continue;
    if (!options.calib.empty()) {
      if (log.id != in_use.id && !options.override_log_calibration) {
        fatal("--calib " + options.calib + " is calibration " +
              laserline::hal::calibration_id_text(in_use.id) + ", but " + options.inputs[i] +
              " was recorded with calibration " + laserline::hal::calibration_id_text(log.id) +
              " (" + log.where +
              "); leave out --calib to use the log's, or add --override-log-calibration");
      }
    } else if (!from_log) {
      from_log = std::move(log);
    } else if (log.id != from_log->id) {
      fatal(options.inputs[i] + " was recorded with calibration " +
            laserline::hal::calibration_id_text(log.id) + " (" + log.where + "), " +
            from_log->where + " with calibration " +
            laserline::hal::calibration_id_text(from_log->id) +
            ": extract them apart, or give --calib");
    }
  }
  if (options.calib.empty()) {
    if (!from_log) {
      usage_error(
          "--calib is required: no input is an LCM log that carries a "
          "laserline.calibration_t");
    }
    if (!from_log->calibration) {
      usage_error("--calib is required: the profiles of " + from_log->where + " name calibration " +
                  laserline::hal::calibration_id_text(from_log->id) +
                  ", but no laserline.calibration_t in the log carries it");
    }
    calibration = *from_log->calibration;
    in_use.id = from_log->id;
    const std::string log_path = from_log->where.substr(0, from_log->where.find(" event "));
    in_use.name = log_path + "'s calibration_t";
    options.calib = in_use.name;  // names the calibration in messages
    std::fprintf(stderr, "laserline-extract: calibration %s from the log %s\n",
                 laserline::hal::calibration_id_text(in_use.id).c_str(), log_path.c_str());
  }
  laserline::pipeline::DetectorOptions detector_options;
  std::string depth_range_note;
  try {
    // The configuration's detector section (thresholds, front-end, motion); its calibration is
    // replaced by --calib.
    const laserline::daemon::DaemonConfig config =
        options.config.empty() ? laserline::daemon::builtin_config()
                               : laserline::daemon::load_config_file(options.config);
    detector_options = config.detector_options;
    detector_options.geometry = laserline::daemon::scanner_geometry(calibration);
    if (laserline::daemon::searches_depth_range(options.detector)) {
      depth_range_note = choose_depth_range(options, calibration, detector_options.frontend);
    }
    // Before any frame: a sheet the camera cannot see would give no point, or none in 3-D.
    laserline::daemon::check_laser_sheet_in_view(
        calibration, {options.calib, "laser"},
        laserline::daemon::searches_depth_range(options.detector) ? &detector_options.frontend
                                                                  : nullptr,
        options.depth_range.empty() ? config.source : "--depth-range " + options.depth_range);
  } catch (const ConfigError& e) {
    fatal(e.what());
  }
  apply_threshold(options, detector_options);
  options.clipped_from = detector_options.frontend.saturation_level;
  const Region region = region_of(options, calibration.camera.width, calibration.camera.height,
                                  &detector_options.roi);
  std::unique_ptr<laserline::pipeline::Detector> detector;
  try {
    detector = laserline::pipeline::make_detector(options.detector, detector_options);
  } catch (const laserline::pipeline::OptionError& e) {
    if (e.field() != "roi") fatal("--detector " + options.detector + ": " + e.what());
    // (--roi was checked above: the configuration's.)
    fatal((options.config.empty() ? std::string("built-in configuration") : options.config) +
          ": detector.roi: " + e.problem() + " of the calibration " + options.calib);
  } catch (const std::invalid_argument& e) {
    fatal("--detector " + options.detector + ": " + e.what());
  }
  if (!detector) fatal("--detector: unknown detector '" + options.detector + "'");
  std::fputs(depth_range_note.c_str(), stderr);

  if (!options.overlay_dir.empty()) {
    std::error_code ec;
    fs::create_directories(options.overlay_dir, ec);
    if (ec || !fs::is_directory(options.overlay_dir)) {
      fatal("--overlay-dir " + options.overlay_dir +
            ": cannot be created: " + (ec ? ec.message() : std::string("not a directory")));
    }
  }
  std::optional<laserline::tools::PoseLog> poses;
  std::optional<laserline::tools::PlyWriter> ply;
  try {
    if (!options.poses.empty()) poses = laserline::tools::PoseLog::load(options.poses);
    if (!options.ply.empty()) {
      ply.emplace(options.ply, poses ? "laserline-extract: metres, world frame of " + options.poses
                                     : std::string("laserline-extract: metres, camera frame"));
    }
  } catch (const laserline::tools::PointCloudError& e) {
    fatal(e.what());
  }
  FILE* csv = nullptr;
  const bool csv_to_stdout = options.output == "-";
  const std::string csv_name = laserline::tools::extract::output_name(options);
  if (csv_to_stdout) {
    csv = stdout;
  } else if (!options.output.empty()) {
    csv = std::fopen(options.output.c_str(), "w");
    if (csv == nullptr) {
      fatal("--output " + options.output + ": cannot be written: " + std::strerror(errno));
    }
  }
  if (csv != nullptr) {
    std::fputs("frame,source,u,v,x,y,snr_db,segment,valid\n", csv);
    std::fflush(csv);
  }

  const double stated_sheet_width = detector_options.geometry.sheet_width_m;
  // The width first (filters sized for a line far wider or narrower than the calibration says
  // show it faintly, in laser-on and laser-off frames alike), then whether the laser alternates;
  // if it does, the width again on the laser-on frames alone.
  fit_sheet_width(options, calibration, region, kinds, in_use, detector_options);
  if (detect_laser_alternation(options, calibration, region, kinds, in_use, detector_options))
    fit_sheet_width(options, calibration, region, kinds, in_use, detector_options);
  if (detector_options.geometry.sheet_width_m != stated_sheet_width) {
    detector = laserline::pipeline::make_detector(options.detector, detector_options);
  }
  Extractor x(options, calibration, std::move(detector), region, csv, ply ? &*ply : nullptr,
              poses ? &*poses : nullptr);
  laserline::tools::extract::extract_inputs(x, options.inputs, kinds, in_use);
  x.progress().clear();
  bool csv_whole = true;
  if (csv != nullptr) {
    // A full disk: the CSV is not whole, which the summary must not hide.
    csv_whole = std::ferror(csv) == 0 && (csv_to_stdout ? std::fflush(csv) : std::fclose(csv)) == 0;
    if (!csv_whole) {
      std::fprintf(stderr, "laserline-extract: --output %s: could not be written completely\n",
                   csv_name.c_str());
    }
  }
  const std::string problems =
      x.failures() > 0 ? ", " + std::to_string(x.failures()) + " problems (see above)" : "";
  std::string written;
  if (csv != nullptr) {
    written = ", " + std::to_string(x.points_written()) + " points written (" +
              std::to_string(x.valid_written()) + " valid) to " + csv_name;
  }
  std::fprintf(stderr,
               "laserline-extract: %lld frames from %zu inputs, %lld processed with %s%s%s\n",
               static_cast<long long>(x.frames()), options.inputs.size(),
               static_cast<long long>(x.processed()), options.detector.c_str(), written.c_str(),
               problems.c_str());
  if (ply) {
    std::fprintf(stderr, "laserline-extract: %lld 3-D points in %s (%s)\n",
                 static_cast<long long>(ply->count()), options.ply.c_str(),
                 poses ? ("world frame of " + options.poses).c_str() : "camera frame");
  }
  const std::int64_t laser_off = x.laser_off_recorded() + x.laser_off_by_pattern();
  if (laser_off > 0) {
    std::string from;
    if (x.laser_off_recorded() > 0) {
      from = std::to_string(x.laser_off_recorded()) + " from the log's profiles";
    }
    if (x.laser_off_by_pattern() > 0) {
      from += (from.empty() ? "" : ", ") + std::to_string(x.laser_off_by_pattern()) +
              " from --laser-pattern " + options.laser_pattern;
    }
    std::fprintf(stderr,
                 "laserline-extract: %lld of the processed frames were exposed with the laser off "
                 "(%s): no points taken from them\n",
                 static_cast<long long>(laser_off), from.c_str());
  }
  if (x.overflowed_frames() > 0) {
    std::fprintf(stderr, "laserline-extract: %lld frames had more points than the detector keeps\n",
                 static_cast<long long>(x.overflowed_frames()));
  }
  // A run that read frames but has nothing to show for them is not a success.
  bool empty_result = false;
  if (x.processed() > 0 && x.accepted() == 0) {
    std::fprintf(stderr,
                 "laserline-extract: no point accepted in any of the %lld processed frames (see "
                 "--channel, --threshold, --roi, --mask, --laser-pattern, --detector)\n",
                 static_cast<long long>(x.processed()));
    empty_result = true;
  }
  const std::int64_t dropped = x.cloud_accepted() - x.cloud_triangulated();
  if (ply && dropped * 2 > x.cloud_accepted()) {
    std::fprintf(stderr,
                 "laserline-extract: %lld of %lld accepted points (%.1f%%) have no 3-D point and "
                 "are left out of %s: their rays do not meet the laser sheet of %s in front of "
                 "the camera (is its plane's sign or the laser's side wrong?)\n",
                 static_cast<long long>(dropped), static_cast<long long>(x.cloud_accepted()),
                 100.0 * static_cast<double>(dropped) / static_cast<double>(x.cloud_accepted()),
                 options.ply.c_str(), options.calib.c_str());
    empty_result = true;
  }
  if (empty_result) return 3;
  return x.failures() > 0 || !csv_whole ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_extract);
}
