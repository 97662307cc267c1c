// The calibration's result from the fitted plane: residuals, sheet width, baseline and angle.
#include <algorithm>
#include <cmath>
#include <limits>

#include "tools/plane_calibration_stages.hpp"

namespace laserline::tools {

void report_plane(CalibrationRun& run, const std::vector<BoardView>& boards, const Plane& plane,
                  const std::vector<char>& use, const hal::CameraIntrinsics& cam) {
  const PlaneCalibrationOptions& o = run.options;
  PlaneCalibrationResult& result = run.result;
  const cv::Matx33d k = camera_matrix(cam);
  // Residuals in mm (3-D) and px (image line of the plane on each board).
  double sq_mm = 0, sq_px = 0;
  int inliers = 0;
  std::vector<double> view_sq(boards.size(), 0.0);
  std::vector<double> widths;  // of the inliers whose width could be measured
  result.depth_min_m = std::numeric_limits<double>::infinity();
  result.depth_max_m = 0;
  for (std::size_t i = 0, at = 0; i < boards.size(); ++i) {
    const BoardView& b = boards[i];
    // The plane through the camera centre containing the 3-D line (laser plane x board plane).
    const cv::Vec3d m = b.offset * plane.normal + plane.e * b.normal;
    const cv::Vec3d m_px = k.inv().t() * m;
    const double m_norm = std::hypot(m_px[0], m_px[1]);
    for (std::size_t j = 0; j < b.laser_xyz.size(); ++j, ++at) {
      if (!use[at]) continue;
      const double mm = 1000.0 * std::abs(plane.normal.dot(b.laser_xyz[j]) + plane.e);
      const cv::Point2d& u = b.laser_px[j];
      const double px = std::abs(m_px[0] * u.x + m_px[1] * u.y + m_px[2]) / m_norm;
      if (std::isfinite(b.sheet_width_m[j])) widths.push_back(b.sheet_width_m[j]);
      result.depth_min_m = std::min(result.depth_min_m, b.laser_xyz[j][2]);
      result.depth_max_m = std::max(result.depth_max_m, b.laser_xyz[j][2]);
      sq_mm += mm * mm;
      sq_px += px * px;
      view_sq[i] += mm * mm;
      result.plane_max_mm = std::max(result.plane_max_mm, mm);
      result.plane_max_px = std::max(result.plane_max_px, px);
      ++inliers;
      ++result.views[b.index].plane_inliers;
    }
  }
  result.inliers = inliers;
  result.plane_rms_mm = std::sqrt(sq_mm / inliers);
  result.plane_rms_px = std::sqrt(sq_px / inliers);
  for (std::size_t i = 0; i < boards.size(); ++i) {
    ViewReport& r = result.views[boards[i].index];
    r.plane_rms_mm = r.plane_inliers > 0 ? std::sqrt(view_sq[i] / r.plane_inliers) : 0.0;
  }
  result.normal_angle_to_y_deg = std::acos(std::clamp(std::abs(plane.normal[1]), 0.0, 1.0)) / kDeg;

  result.calibration.camera = cam;
  hal::LaserMount& laser = result.calibration.laser;
  laser = o.laser_prior;
  laser.plane = Eigen::Vector4d{plane.normal[0], plane.normal[1], plane.normal[2], plane.e};
  // The sheet's width as the camera sees it (its thickness, blurred by the optics): the
  // front-end's band-pass is made for it. A third of the inliers must give it.
  result.width_points = static_cast<int>(widths.size());
  if (o.measure_sheet_width && 3 * widths.size() >= static_cast<std::size_t>(inliers)) {
    result.sheet_width_measured = true;
    laser.sheet_width_m = std::clamp(median(widths), 1e-5, 0.1);
  }
  // The paper's model Y = -d + tan(90 deg - beta) Z with the sheet along x, turned to the side
  // of the camera the projector is on: the axis the plane's normal leans to most (y above or
  // below, x left or right; e > 0 gives the sign). d where the plane crosses that axis, beta
  // from its slope toward the optical axis. Kept within the file's limits.
  const double a = plane.normal[0], b = plane.normal[1];
  double along = 0;
  if (std::abs(b) >= std::abs(a)) {
    laser.side = b > 0 ? hal::LaserSide::kAbove : hal::LaserSide::kBelow;
    along = std::abs(b);
  } else {
    laser.side = a > 0 ? hal::LaserSide::kLeft : hal::LaserSide::kRight;
    along = std::abs(a);
  }
  const double baseline = along > 0 ? plane.e / along : 0.0;
  const double angle = 90.0 - std::atan2(-plane.normal[2], along) / kDeg;
  result.fits_baseline_model = baseline >= 1e-3 && baseline <= 10 && angle >= 1 && angle <= 179;
  laser.baseline_m = std::clamp(baseline, 1e-3, 10.0);
  laser.angle_deg = std::clamp(angle, 1.0, 179.0);
}

}  // namespace laserline::tools
