// The homography between consecutive frames from tracked features: four-point samples by bounded
// RANSAC (MSAC cost) on Hartley-normalised coordinates, then a least-squares refit (normalised
// DLT) on the inliers; and Homography's inverse and composition.
#include "pipeline/homography.hpp"

#include <algorithm>
#include <cmath>

#include "pipeline/motion.hpp"
#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

namespace {

// Similarity that moves the points' centroid to the origin and their mean distance to sqrt(2)
// (Hartley's normalisation, which keeps the DLT well conditioned).
Matrix3 normalising_transform(const double* x, const double* y, const int* index, int count) {
  double cx = 0, cy = 0;
  for (int i = 0; i < count; ++i) {
    cx += x[index[i]];
    cy += y[index[i]];
  }
  cx /= count;
  cy /= count;
  double mean_distance = 0;
  for (int i = 0; i < count; ++i)
    mean_distance += std::hypot(x[index[i]] - cx, y[index[i]] - cy);
  mean_distance /= count;
  const double s = mean_distance > 1e-12 ? std::sqrt(2.0) / mean_distance : 1.0;
  Matrix3 t;
  t << s, 0, -s * cx, 0, s, -s * cy, 0, 0, 1;
  return t;
}

Homography to_homography(const Matrix3& m_in) {
  Matrix3 m = m_in;
  if (std::abs(m(2, 2)) > 1e-12) {
    m /= m(2, 2);
  } else {
    m /= m.norm();
  }
  Homography h;
  h.h = m;
  return h;
}

// Twice the signed area of the triangle a, b, c.
double twice_area(double ax, double ay, double bx, double by, double cx, double cy) {
  return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
}

using Matrix8 = Eigen::Matrix<double, 8, 8>;
using Vector8 = Eigen::Matrix<double, 8, 1>;
using Matrix9 = Eigen::Matrix<double, 9, 9>;
using Vector9 = Eigen::Matrix<double, 9, 1>;

// Homography through four correspondences (h33 = 1; with the points normalised around their
// centroid h33 = 0 would need a transformation far beyond any frame-to-frame motion).
bool minimal_homography(const double* x, const double* y, const double* xp, const double* yp,
                        Matrix3& out) {
  Matrix8 a;
  Vector8 b;
  for (int k = 0; k < 4; ++k) {
    a.row(2 * k) << x[k], y[k], 1, 0, 0, 0, -x[k] * xp[k], -y[k] * xp[k];
    a.row(2 * k + 1) << 0, 0, 0, x[k], y[k], 1, -x[k] * yp[k], -y[k] * yp[k];
    b(2 * k) = xp[k];
    b(2 * k + 1) = yp[k];
  }
  const Eigen::FullPivLU<Matrix8> lu(a);
  if (!lu.isInvertible()) return false;
  const Vector8 h = lu.solve(b);
  out << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), 1;
  return out.allFinite();
}

}  // namespace

namespace motion_detail {

Matrix3 to_matrix(const Homography& h) {
  return h.h;
}

}  // namespace motion_detail

Homography Homography::inverse() const {
  const Matrix3 m = to_matrix(*this);
  const double det = m.determinant();
  if (!(std::abs(det) > 0)) return Homography{Homography::Matrix::Zero()};
  // The adjugate is the inverse up to scale, and a homography is defined up to scale only.
  Matrix3 adjugate;
  adjugate(0, 0) = m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1);
  adjugate(0, 1) = m(0, 2) * m(2, 1) - m(0, 1) * m(2, 2);
  adjugate(0, 2) = m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1);
  adjugate(1, 0) = m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2);
  adjugate(1, 1) = m(0, 0) * m(2, 2) - m(0, 2) * m(2, 0);
  adjugate(1, 2) = m(0, 2) * m(1, 0) - m(0, 0) * m(1, 2);
  adjugate(2, 0) = m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0);
  adjugate(2, 1) = m(0, 1) * m(2, 0) - m(0, 0) * m(2, 1);
  adjugate(2, 2) = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
  return to_homography(adjugate / det);
}

Homography Homography::after(const Homography& first) const {
  return to_homography(to_matrix(*this) * to_matrix(first));
}

bool MotionEstimator::fit_homography(int n, Homography& result, int& inlier_count) {
  State& s = *state_;
  const MotionOptions& o = options_;
  const double* px = s.px.data();
  const double* py = s.py.data();
  const double* cx = s.cx.data();
  const double* cy = s.cy.data();
  const double threshold_squared = o.inlier_px * o.inlier_px;

  // Errors in full-size pixels of the current frame; MSAC cost (inliers by their error, outliers
  // by the threshold) picks the better of two hypotheses with as many inliers.
  const auto score = [&](const Matrix3& h, std::uint8_t* flags, int& count) {
    double cost = 0;
    count = 0;
    for (int i = 0; i < n; ++i) {
      const double w = h(2, 0) * px[i] + h(2, 1) * py[i] + h(2, 2);
      const double ex = (h(0, 0) * px[i] + h(0, 1) * py[i] + h(0, 2)) / w - cx[i];
      const double ey = (h(1, 0) * px[i] + h(1, 1) * py[i] + h(1, 2)) / w - cy[i];
      const double e = ex * ex + ey * ey;
      const bool inlier = w > 0 && e < threshold_squared;
      flags[i] = inlier ? 1 : 0;
      count += inlier ? 1 : 0;
      cost += inlier ? e : threshold_squared;
    }
    return cost;
  };

  const Matrix3 t_previous = normalising_transform(px, py, s.all_index.data(), n);
  const Matrix3 t_current = normalising_transform(cx, cy, s.all_index.data(), n);
  const Matrix3 t_current_inverse = t_current.inverse();

  Random random{kRansacSeed};
  double best_cost = 0;
  int best_count = 0;
  bool found = false;
  int iterations_needed = o.ransac_iterations;
  for (int iteration = 0; iteration < iterations_needed; ++iteration) {
    // Four distinct tracks: the first steps of a Fisher-Yates shuffle (bounded, no retries).
    int* order = s.all_index.data();
    int pick[4];
    for (int k = 0; k < 4; ++k) {
      std::swap(order[k], order[k + random.below(n - k)]);
      pick[k] = order[k];
    }
    double x[4], y[4], xp[4], yp[4];
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d a = t_previous * Eigen::Vector3d(px[pick[k]], py[pick[k]], 1);
      const Eigen::Vector3d b = t_current * Eigen::Vector3d(cx[pick[k]], cy[pick[k]], 1);
      x[k] = a(0);
      y[k] = a(1);
      xp[k] = b(0);
      yp[k] = b(1);
    }
    // Three nearly collinear points make the sample degenerate.
    bool degenerate = false;
    for (int k = 0; k < 4 && !degenerate; ++k) {
      const int i0 = (k + 1) % 4, i1 = (k + 2) % 4, i2 = (k + 3) % 4;
      degenerate = std::abs(twice_area(x[i0], y[i0], x[i1], y[i1], x[i2], y[i2])) < 1e-2 ||
                   std::abs(twice_area(xp[i0], yp[i0], xp[i1], yp[i1], xp[i2], yp[i2])) < 1e-2;
    }
    if (degenerate) continue;
    Matrix3 h_normalised;
    if (!minimal_homography(x, y, xp, yp, h_normalised)) continue;
    const Matrix3 h = t_current_inverse * h_normalised * t_previous;
    int count = 0;
    const double cost = score(h, s.is_inlier.data(), count);
    if (!found || cost < best_cost) {
      found = true;
      best_cost = cost;
      best_count = count;
      std::copy(s.is_inlier.begin(), s.is_inlier.begin() + n, s.best_inlier.begin());
      // Stop once a sample of all inliers has been drawn with the wanted confidence.
      const double inlier_ratio = static_cast<double>(count) / n;
      const double all_inliers = std::pow(inlier_ratio, 4);
      if (all_inliers >= 1.0) {
        iterations_needed = std::min(iterations_needed, iteration + 1);
      } else if (all_inliers > 0) {
        const double needed = std::log(1 - kRansacConfidence) / std::log(1 - all_inliers) + 1;
        if (needed < iterations_needed) iterations_needed = static_cast<int>(needed);
      }
    }
  }
  if (!found || best_count < 4) return false;

  // Least-squares refit on the inliers (normalised DLT), repeated while the inlier set grows.
  std::copy(s.best_inlier.begin(), s.best_inlier.begin() + n, s.is_inlier.begin());
  Matrix3 h_best;
  int count = best_count;
  bool refitted = false;
  for (int round = 0; round < 3; ++round) {
    int m = 0;
    for (int i = 0; i < n; ++i)
      if (s.is_inlier[i]) s.inlier_index[m++] = i;
    if (m < 4) break;
    const Matrix3 tp = normalising_transform(px, py, s.inlier_index.data(), m);
    const Matrix3 tc = normalising_transform(cx, cy, s.inlier_index.data(), m);
    Matrix9 normal = Matrix9::Zero();
    for (int k = 0; k < m; ++k) {
      const int i = s.inlier_index[k];
      const double x = tp(0, 0) * px[i] + tp(0, 2), y = tp(1, 1) * py[i] + tp(1, 2);
      const double xp = tc(0, 0) * cx[i] + tc(0, 2), yp = tc(1, 1) * cy[i] + tc(1, 2);
      Vector9 r1, r2;
      r1 << x, y, 1, 0, 0, 0, -xp * x, -xp * y, -xp;
      r2 << 0, 0, 0, x, y, 1, -yp * x, -yp * y, -yp;
      normal.noalias() += r1 * r1.transpose();
      normal.noalias() += r2 * r2.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Matrix9> solver(normal);
    if (solver.info() != Eigen::Success) break;
    const Vector9 v = solver.eigenvectors().col(0);
    Matrix3 h_normalised;
    h_normalised << v(0), v(1), v(2), v(3), v(4), v(5), v(6), v(7), v(8);
    const Matrix3 h = tc.inverse() * h_normalised * tp;
    if (!h.allFinite() || std::abs(h(2, 2)) < 1e-12) break;
    const Matrix3 h_scaled = h / h(2, 2);
    int new_count = 0;
    score(h_scaled, s.best_inlier.data(), new_count);
    h_best = h_scaled;
    refitted = true;
    const bool grew = new_count > count;
    count = new_count;
    std::copy(s.best_inlier.begin(), s.best_inlier.begin() + n, s.is_inlier.begin());
    if (!grew) break;
  }
  if (!refitted) return false;
  result = to_homography(h_best);
  inlier_count = count;
  return true;
}

}  // namespace laserline::pipeline
