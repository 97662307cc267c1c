#include "hal/sim/sim_lines.hpp"

#include <algorithm>
#include <cmath>

#include "hal/sim/sim_surface.hpp"

namespace laserline::hal {

SimLineFamily SimLineFamily::columns(int width) {
  SimLineFamily lines;
  lines.count = width;
  return lines;
}

SimLineFamily epipolar_lines(const Calibration& calibration) {
  const CameraIntrinsics& cam = calibration.camera;
  const Eigen::Vector4d plane = calibration.laser.plane_coefficients();
  const double gu = plane[0] / cam.fx, gv = plane[1] / cam.fy;
  const double norm = std::hypot(gu, gv);
  const double tolerance = std::tan(5.0 * sim::kDeg);
  if (!(norm > 0) || std::abs(gu) <= tolerance * std::abs(gv)) {
    return SimLineFamily::columns(cam.width);
  }
  SimLineFamily lines;
  if (std::abs(gv) <= tolerance * std::abs(gu)) {
    lines.line_step = {0.0, 1.0};
    lines.along = {1.0, 0.0};
    lines.count = cam.height;
    return lines;
  }
  const double sign = gv < 0 ? -1.0 : 1.0;
  lines.along = {sign * gu / norm, sign * gv / norm};
  lines.line_step = {lines.along[1], -lines.along[0]};
  double lo = 1e300, hi = -1e300, position_lo = 1e300;
  for (const double x : {0.0, static_cast<double>(cam.width - 1)}) {
    for (const double y : {0.0, static_cast<double>(cam.height - 1)}) {
      const auto [line, position] = lines.to_family(x, y);
      lo = std::min(lo, line);
      hi = std::max(hi, line);
      position_lo = std::min(position_lo, position);
    }
  }
  lo = std::floor(lo);
  position_lo = std::floor(position_lo);
  lines.origin = {lo * lines.line_step[0] + position_lo * lines.along[0],
                  lo * lines.line_step[1] + position_lo * lines.along[1]};
  lines.count = static_cast<int>(std::ceil(hi - lo)) + 1;
  return lines;
}

namespace sim {

Mat3 rot_x(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 m;
  m << 1, 0, 0, 0, c, -s, 0, s, c;
  return m;
}
Mat3 rot_y(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 m;
  m << c, 0, s, 0, 1, 0, -s, 0, c;
  return m;
}
Mat3 rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 m;
  m << c, -s, 0, s, c, 0, 0, 0, 1;
  return m;
}

FrameGeometry make_geometry(const SimSceneOptions& o, const Mat3& r, const Vec3& t,
                            double object_shift_m) {
  FrameGeometry g;
  g.object_shift_m = object_shift_m;
  const CameraIntrinsics& cam = o.calibration.camera;
  g.fx = cam.fx;
  g.fy = cam.fy;
  g.cx = cam.cx;
  g.cy = cam.cy;
  g.lp = o.calibration.laser.plane_coefficients();
  if (o.laser_fan_deg > 0) {
    const Vec3 normal = g.lp.head<3>().normalized();
    g.fan_apex = -g.lp[3] / g.lp.head<3>().norm() * normal;
    g.fan_axis = (Vec3::UnitZ() - normal.z() * normal).normalized();
    g.fan_side = normal.cross(g.fan_axis);
    g.fan_tan_half = std::tan(0.5 * o.laser_fan_deg * kDeg);
  }

  // The surface in the world: through p0, normal n_w toward the camera, texture axes e1, e2.
  const Mat3 basis = rot_x(o.tilt_x_deg * kDeg) * rot_y(o.tilt_y_deg * kDeg);
  const Vec3 e1 = basis.col(0);
  const Vec3 e2 = basis.col(1);
  const Vec3 n_w = -basis.col(2);
  const Vec3 p0(0.0, 0.0, o.distance_m);

  // In the camera frame: n_c . X = D with n_c = -R^T n_w, D = n_w . T - n_w . p0 (> 0 in front).
  g.n = -(r.transpose() * n_w);
  g.d_surface = n_w.dot(t) - n_w.dot(p0);
  g.surface = g.d_surface > 0;
  if (!g.surface) return g;

  // Texture coordinate s = e1 . (X_w - p0) = Z (R^T e1) . r + e1 . (T - p0) with Z = D / (n_c . r),
  // so s (n_c . r) is linear in the ray r: a homography, here in texels and pixel coordinates.
  const double texel = o.texture_scale_m / kFinestSpacing;
  const Vec3 tp = t - p0;
  const Vec3 re1 = r.transpose() * e1, re2 = r.transpose() * e2;
  const double c1 = e1.dot(tp), c2 = e2.dot(tp);
  g.e1 = re1;
  g.e2 = re2;
  g.c1 = c1;
  g.c2 = c2;
  g.texel_m = texel;
  const std::array<Vec3, 3> rows{(g.d_surface * re1 + c1 * g.n) / texel,
                                 (g.d_surface * re2 + c2 * g.n) / texel, g.n};
  for (int i = 0; i < 3; ++i) {
    const Vec3& m = rows[i];
    g.h(i, 0) = m[0] / g.fx;
    g.h(i, 1) = m[1] / g.fy;
    g.h(i, 2) = m[2] - m[0] * g.cx / g.fx - m[1] * g.cy / g.fy;
  }
  return g;
}

float albedo_at(const FrameGeometry& g, const float* tex, double u, double v) {
  const double s = g.h(0, 0) * u + g.h(0, 1) * v + g.h(0, 2);
  const double t = g.h(1, 0) * u + g.h(1, 1) * v + g.h(1, 2);
  const double w = g.h(2, 0) * u + g.h(2, 1) * v + g.h(2, 2);
  if (!(w > 0)) return 0.0f;
  return sample_tile(tex, static_cast<float>(std::clamp(s / w, -1e7, 1e7)),
                     static_cast<float>(std::clamp(t / w, -1e7, 1e7)));
}

// Where the sheet meets the relieved surface along column u. The sheet's points in the column
// form a line P + l D (the sheet cut by the plane through the camera and the column); the relief
// lies between heights 0 and relief_max, so the crossing is within the stretch of that line
// between those heights. Walked from the top in steps of at most one lattice cell, then bisected
// to double precision: the bilinear surface is continuous, so the sign change brackets a root.

namespace {

// The rays of an image line: normalised image coordinates x0 + s dx, y0 + s dy at position s.
struct LineRays {
  double x0, y0, dx, dy;
};

LineRays rays_of(const FrameGeometry& g, const SimLineFamily& lines, double k) {
  const auto [ox, oy] = lines.to_image(k, 0.0);
  return {(ox - g.cx) / g.fx, (oy - g.cy) / g.fy, lines.along[0] / g.fx, lines.along[1] / g.fy};
}

// In closed form on the flat surface: with X = Z (xn, yn, 1) the sheet gives
// Z (a xn + b yn + c) = -e and the surface Z (n . r) = D; eliminating Z is linear in the position.
LineHit solve_flat(const FrameGeometry& g, const SimLineFamily& lines, double k) {
  LineHit out;
  if (!g.surface) return out;
  const double a = g.lp[0], b = g.lp[1], c = g.lp[2], e = g.lp[3];
  const LineRays r = rays_of(g, lines, k);
  const double d = g.d_surface;
  const double k0 = -e * (g.n[0] * r.x0 + g.n[1] * r.y0 + g.n[2]) - d * (a * r.x0 + b * r.y0 + c);
  const double k1 = -e * (g.n[0] * r.dx + g.n[1] * r.dy) - d * (a * r.dx + b * r.dy);
  if (!(std::abs(k1) * std::max(g.fx, g.fy) > 1e-12)) return out;
  const double s = -k0 / k1;
  const double nr = g.n[0] * (r.x0 + s * r.dx) + g.n[1] * (r.y0 + s * r.dy) + g.n[2];
  if (!(nr > 0)) return out;
  out.z = d / nr;
  out.position = s;
  out.hit = std::isfinite(out.position) && std::isfinite(out.z) && out.z > 0;
  return out;
}

// On the relief: the sheet's points seen along the image line form a line P + l D (the sheet cut
// by the plane through the camera and the image line); the relief lies between heights 0 and
// relief_max, so the crossing is within the stretch of that line between those heights. Walked
// from the top in steps of at most one lattice cell, then bisected to double precision: the
// bilinear surface is continuous, so the sign change brackets a root. The first crossing from the
// top is the lit one (the slope limit makes it the only one).
LineHit solve_relief(const FrameGeometry& g, const SimLineFamily& lines, double k,
                     const float* relief, double relief_max) {
  LineHit out;
  if (!g.surface) return out;
  const double e = g.lp[3];
  const LineRays r = rays_of(g, lines, k);
  // The plane's normal: the line's direction (scaled to unit largest component) times its first
  // ray; for a column u exactly (1, 0, -xn).
  const double scale = std::max(std::abs(r.dx), std::abs(r.dy));
  const double d0 = r.dx / scale, d1 = r.dy / scale;
  const Vec3 n1(d1, -d0, d0 * r.y0 - d1 * r.x0), n2 = g.lp.head<3>();
  const Vec3 dir = n1.cross(n2);
  // P = alpha n1 + beta n2 with n1 . P = 0 (in the line's plane) and n2 . P = -e (on the sheet).
  const double g11 = n1.dot(n1), g12 = n1.dot(n2), g22 = n2.dot(n2);
  const double det = g11 * g22 - g12 * g12;
  if (!(det > 1e-18 * g11 * g22)) return out;
  const double alpha = e * g12 / det, beta = -e * g11 / det;
  const Vec3 p = alpha * n1 + beta * n2;
  // Height above the base plane along the line: q0 - l qd.
  const double q0 = g.d_surface - g.n.dot(p), qd = g.n.dot(dir);
  if (!(std::abs(qd) > 1e-12)) return out;
  const double margin = 1e-3;
  const double l_top = (q0 - (relief_max + margin)) / qd, l_bottom = (q0 + margin) / qd;
  const double x0 = g.e1.dot(p) + g.c1, xd = g.e1.dot(dir);
  const double y0 = g.e2.dot(p) + g.c2, yd = g.e2.dot(dir);
  // The relief (the objects on the surface) has moved by object_shift_m along x.
  const double shift = g.object_shift_m;
  auto height = [&](double l) { return relief_at(relief, x0 + l * xd - shift, y0 + l * yd); };
  auto above = [&](double l) { return (q0 - l * qd) - height(l); };
  const double span = std::abs(l_bottom - l_top) * std::hypot(xd, yd);
  const int steps = static_cast<int>(std::clamp(std::ceil(span / kReliefCellM), 2.0, 100000.0));
  double lo = l_top, hi = l_bottom;  // above(lo) > 0 >= above(hi) once bracketed
  for (int step = 1; step <= steps; ++step) {
    const double l = l_top + (l_bottom - l_top) * step / steps;
    if (above(l) <= 0) {
      hi = l;
      break;
    }
    lo = l;
  }
  for (int step = 0; step < 200 && lo != hi; ++step) {
    const double mid = 0.5 * (lo + hi);
    if (mid == lo || mid == hi) break;
    (above(mid) > 0 ? lo : hi) = mid;
  }
  const double l = 0.5 * (lo + hi);
  const Vec3 x = p + l * dir;
  if (!(x[2] > 0)) return out;
  out.z = x[2];
  const double u = g.cx + g.fx * x[0] / x[2], v = g.cy + g.fy * x[1] / x[2];
  out.position = lines.to_family(u, v)[1];
  // The texture on an object moves with it; on the bare surface it stays.
  const double texture_shift = shift != 0 && height(l) > 1e-4 ? shift : 0.0;
  out.s = (x0 + l * xd - texture_shift) / g.texel_m;
  out.t = (y0 + l * yd) / g.texel_m;
  out.hit = std::isfinite(out.position) && std::isfinite(out.z) && std::isfinite(out.s) &&
            std::isfinite(out.t);
  return out;
}

}  // namespace

LineHit solve_line(const FrameGeometry& g, const SimLineFamily& lines, double k,
                   const float* relief, double relief_max) {
  LineHit hit =
      relief == nullptr ? solve_flat(g, lines, k) : solve_relief(g, lines, k, relief, relief_max);
  if (hit.hit && g.fan_tan_half > 0) {
    const auto [x, y] = lines.to_image(k, hit.position);
    const Vec3 from_apex = hit.z * Vec3((x - g.cx) / g.fx, (y - g.cy) / g.fy, 1.0) - g.fan_apex;
    hit.hit = std::abs(g.fan_side.dot(from_apex)) <= g.fan_tan_half * g.fan_axis.dot(from_apex);
  }
  return hit;
}

double line_sigma(const SimSceneOptions& o, const SimLineFamily& lines, double z) {
  // The sheet's thickness seen across the line, in pixels along the epipolar line.
  const double f = std::hypot(o.calibration.camera.fx * lines.along[0],
                              o.calibration.camera.fy * lines.along[1]);
  const double sheet = f * o.calibration.laser.sheet_width_m / z / 2.3548200450309493;
  return std::max(1e-3, std::sqrt(sheet * sheet + o.blur_px * o.blur_px));
}

}  // namespace sim
}  // namespace laserline::hal
