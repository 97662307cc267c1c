#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "tools/frame_channel.hpp"
#include "tools/laser_plane_calibration.hpp"

// laser_plane_calibration.hpp's files: the calibration written, the views' images read.
namespace laserline::tools {

namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& message) {
  throw PlaneCalibrationError(message);
}

}  // namespace

void write_calibration_file(const std::string& path, const PlaneCalibrationResult& r,
                            const std::string& provenance) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) fail(path + ": cannot be written: " + std::strerror(errno));
  const hal::CameraIntrinsics& c = r.calibration.camera;
  const hal::LaserMount& l = r.calibration.laser;
  const auto p = l.plane_coefficients();
  std::fprintf(f, "# laserline calibration written by laserline-calibrate\n");
  std::fprintf(f, "# %s\n", provenance.c_str());
  if (r.intrinsics_estimated) {
    std::fprintf(f, "# camera: estimated, calibrateCamera RMS %.3f px\n", r.camera_rms_px);
  } else {
    std::fprintf(f, "# camera: given\n");
  }
  std::fprintf(f, "# board corners reprojected: RMS %.3f px\n", r.corner_rms_px);
  std::fprintf(f,
               "# laser plane fit: %d of %d points, distance RMS %.3f mm, max %.3f mm; image RMS "
               "%.3f px, max %.3f px\n",
               r.inliers, r.points, r.plane_rms_mm, r.plane_max_mm, r.plane_rms_px, r.plane_max_px);
  std::fprintf(f,
               "# the line was seen at depths %.3f to %.3f m: detector.frontend.min_depth_m and "
               "max_depth_m must cover the working range\n",
               r.depth_min_m, r.depth_max_m);
  std::fprintf(f,
               "camera: {width: %d, height: %d, fx: %.10g, fy: %.10g, cx: %.10g, cy: %.10g, "
               "distortion: [%.10g, %.10g, %.10g, %.10g, %.10g]}\n",
               c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.distortion[0], c.distortion[1],
               c.distortion[2], c.distortion[3], c.distortion[4]);
  std::fprintf(f, "laser:\n");
  std::fprintf(f, "  # the paper's d and beta nearest to the plane%s; `plane` is what is used\n",
               r.fits_baseline_model ? "" : " (clamped: the plane does not fit that model)");
  std::fprintf(f, "  baseline_m: %.10g\n  angle_deg: %.10g\n  side: %s\n", l.baseline_m,
               l.angle_deg, hal::to_string(l.side));
  if (r.sheet_width_measured) {
    std::fprintf(f,
                 "  # measured: the line's full width at half maximum times its depth over f, "
                 "median of %d points\n",
                 r.width_points);
  }
  std::fprintf(f, "  sheet_width_m: %.10g\n", l.sheet_width_m);
  std::fprintf(f, "  # a*X + b*Y + c*Z + e = 0, camera frame, metres; (a, b, c) a unit vector\n");
  std::fprintf(f, "  plane: [%.12g, %.12g, %.12g, %.12g]\n", p[0], p[1], p[2], p[3]);
  const bool ok = std::ferror(f) == 0;
  if (std::fclose(f) != 0 || !ok) fail(path + ": could not be written completely");
}

cv::Mat load_image(const std::string& path, const hal::LaserChannel& channel) {
  cv::Mat raw;
  std::string problem;
  // A damaged file (cut short) decodes with grey where data is missing: refused, not measured.
  if (!read_image_file(path, raw, problem)) fail(path + ": " + problem);
  cv::Mat out;
  if (!to_laser_mono8(raw, channel, 255, significant_bits(raw), out, problem))
    fail(path + ": " + problem);  // (read only to check it)
  return raw;
}

std::vector<std::string> expand_image_inputs(const std::vector<std::string>& inputs) {
  static const char* const kExtensions[] = {".png", ".jpg", ".jpeg", ".tif", ".tiff",
                                            ".bmp", ".pgm", ".ppm",  ".pnm", ".webp"};
  std::vector<std::string> files;
  for (const auto& input : inputs) {
    std::error_code ec;
    if (fs::is_directory(input, ec)) {
      std::vector<std::string> found;
      for (const auto& entry : fs::directory_iterator(input, ec)) {
        std::string ext = entry.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(),
                       [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
        if (entry.is_regular_file() && std::any_of(std::begin(kExtensions), std::end(kExtensions),
                                                   [&](const char* e) { return ext == e; })) {
          found.push_back(entry.path().string());
        }
      }
      if (ec) fail(input + ": folder cannot be read: " + ec.message());
      std::sort(found.begin(), found.end());
      if (found.empty()) fail(input + ": folder holds no image files");
      files.insert(files.end(), found.begin(), found.end());
    } else if (fs::exists(input, ec)) {
      files.push_back(input);
    } else {
      fail(input + ": no such file or folder");
    }
  }
  return files;
}

}  // namespace laserline::tools
