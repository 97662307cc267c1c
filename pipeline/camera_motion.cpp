// The camera's motion between consecutive frames from the tracks (CameraMotionEstimator):
// five-point RANSAC over Sampson distances, an eight-point refit, cheirality to pick R and t,
// Levenberg-Marquardt on the image error, the rotation-only test for parallax, and the relative
// scale from points followed over three frames.
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pipeline/five_point.hpp"
#include "pipeline/motion.hpp"
#include "pipeline/motion_internal.hpp"

namespace laserline::pipeline {

using namespace motion_detail;

namespace {

using Vector3 = Eigen::Vector3d;

// The Sampson distance of a correspondence to the epipolar geometry E (normalised units) is
// residual / sqrt(denominator).
struct SampsonTerms {
  double residual, denominator;
};

SampsonTerms sampson_terms(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const double ex0 = e(0, 0) * x1 + e(0, 1) * y1 + e(0, 2);
  const double ex1 = e(1, 0) * x1 + e(1, 1) * y1 + e(1, 2);
  const double ex2 = e(2, 0) * x1 + e(2, 1) * y1 + e(2, 2);
  const double etx0 = e(0, 0) * x2 + e(1, 0) * y2 + e(2, 0);
  const double etx1 = e(0, 1) * x2 + e(1, 1) * y2 + e(2, 1);
  return {x2 * ex0 + y2 * ex1 + ex2, ex0 * ex0 + ex1 * ex1 + etx0 * etx0 + etx1 * etx1};
}

// Squared Sampson distance (infinite where it is undefined).
double sampson_squared(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const SampsonTerms s = sampson_terms(e, x1, y1, x2, y2);
  return s.denominator > 0 ? s.residual * s.residual / s.denominator
                           : std::numeric_limits<double>::infinity();
}

// Depths (d1 in the previous camera, d2 in the current one) of the point seen along (x1, y1, 1)
// and (x2, y2, 1), least squares of d2 x2 = d1 R x1 + t. False when the rays are parallel.
bool triangulate_depths(const Matrix3& r, const Vector3& t, double x1, double y1, double x2,
                        double y2, double& d1, double& d2) {
  const Vector3 a = r * Vector3(x1, y1, 1);
  const Vector3 b(x2, y2, 1);
  const double aa = a.dot(a), bb = b.dot(b), ab = a.dot(b), at = a.dot(t), bt = b.dot(t);
  const double det = aa * bb - ab * ab;
  if (!(det > 1e-14 * aa * bb)) return false;
  d1 = (-at * bb + ab * bt) / det;
  d2 = (aa * bt - ab * at) / det;
  return true;
}

// The essential matrix nearest to m (singular values (s, s, 0)), as U, V with det = +1.
bool essential_decomposition(const Matrix3& e, Matrix3& u, Matrix3& v) {
  const Eigen::JacobiSVD<Matrix3> svd(e, Eigen::ComputeFullU | Eigen::ComputeFullV);
  u = svd.matrixU();
  v = svd.matrixV();
  if (u.determinant() < 0) u = -u;
  if (v.determinant() < 0) v = -v;
  return svd.singularValues()(1) > 1e-9 * svd.singularValues()(0);
}

Matrix3 skew(const Vector3& t) {
  Matrix3 m;
  m << 0, -t(2), t(1), t(2), 0, -t(0), -t(1), t(0), 0;
  return m;
}

// Signed Sampson distance (normalised units): its square is sampson_squared() (0 where undefined).
double sampson_signed(const Matrix3& e, double x1, double y1, double x2, double y2) {
  const SampsonTerms s = sampson_terms(e, x1, y1, x2, y2);
  return s.denominator > 0 ? s.residual / std::sqrt(s.denominator) : 0.0;
}

// Levenberg-Marquardt on the inliers' Sampson distances over the five degrees of freedom of
// (R, t / |t|): the minimal and linear solutions fit a few points exactly or minimise an
// algebraic error, this minimises (nearly) the image error. Bounded iterations; the
// Jacobian by forward differences (five more essential matrices per iteration).
void refine_motion(const double* x1, const double* y1, const double* x2, const double* y2,
                   const std::uint8_t* inlier, int n, Matrix3& rotation, Vector3& translation) {
  using Vector5 = Eigen::Matrix<double, 5, 1>;
  using Matrix5 = Eigen::Matrix<double, 5, 5>;
  const auto apply = [](const Matrix3& r, const Vector3& t, const Vector5& delta, Matrix3& r_out,
                        Vector3& t_out) {
    const Vector3 w = delta.head<3>();
    const double angle = w.norm();
    r_out = angle > 0 ? Matrix3(Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() * r) : r;
    // Two directions across t.
    const Vector3 helper = std::abs(t(0)) < 0.9 ? Vector3::UnitX() : Vector3::UnitY();
    const Vector3 b1 = t.cross(helper).normalized();
    const Vector3 b2 = t.cross(b1);
    t_out = (t + delta(3) * b1 + delta(4) * b2).normalized();
  };
  const auto cost = [&](const Matrix3& e) {
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const double d = sampson_signed(e, x1[i], y1[i], x2[i], y2[i]);
      sum += d * d;
    }
    return sum;
  };
  constexpr double kStep = 1e-7;
  double lambda = 1e-3;
  double current = cost(skew(translation) * rotation);
  for (int iteration = 0; iteration < 10; ++iteration) {
    const Matrix3 e = skew(translation) * rotation;
    std::array<Matrix3, 5> moved;
    for (int k = 0; k < 5; ++k) {
      Vector5 delta = Vector5::Zero();
      delta(k) = kStep;
      Matrix3 r;
      Vector3 t;
      apply(rotation, translation, delta, r, t);
      moved[k] = skew(t) * r;
    }
    Matrix5 normal = Matrix5::Zero();
    Vector5 gradient = Vector5::Zero();
    for (int i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const double d = sampson_signed(e, x1[i], y1[i], x2[i], y2[i]);
      Vector5 j;
      for (int k = 0; k < 5; ++k)
        j(k) = (sampson_signed(moved[k], x1[i], y1[i], x2[i], y2[i]) - d) / kStep;
      normal.noalias() += j * j.transpose();
      gradient.noalias() += j * d;
    }
    bool improved = false;
    for (int attempt = 0; attempt < 4 && !improved; ++attempt) {
      Matrix5 damped = normal;
      for (int k = 0; k < 5; ++k)
        damped(k, k) += lambda * std::max(normal(k, k), 1e-12);
      const Vector5 delta = damped.ldlt().solve(-gradient);
      if (!delta.allFinite()) return;
      Matrix3 r;
      Vector3 t;
      apply(rotation, translation, delta, r, t);
      const double candidate = cost(skew(t) * r);
      if (candidate < current) {
        const bool converged = current - candidate < 1e-10 * current;
        rotation = r;
        translation = t;
        current = candidate;
        lambda = std::max(lambda * 0.1, 1e-9);
        improved = true;
        if (converged) return;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) return;
  }
}

Matrix3 project_to_essential(const Matrix3& m) {
  const Eigen::JacobiSVD<Matrix3> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  const double mean = 0.5 * (s(0) + s(1));
  return svd.matrixU() * Eigen::Vector3d(mean, mean, 0).asDiagonal() * svd.matrixV().transpose();
}

}  // namespace

CameraMotionEstimator::CameraMotionEstimator(const MotionOptions& options) : options_(options) {}

void CameraMotionEstimator::reset(const ScannerGeometry& geometry, int max_tracks) {
  if (max_tracks < 0) throw std::invalid_argument("CameraMotionEstimator::reset: max_tracks < 0");
  geometry_ = geometry;
  focal_ = std::sqrt(geometry.fx * geometry.fy);
  const auto size = static_cast<std::size_t>(max_tracks);
  for (auto* v : {&x1_, &y1_, &x2_, &y2_, &residual_})
    v->assign(size, 0);
  order_.assign(size, 0);
  inlier_.assign(size, 0);
  candidate_.assign(size, 0);
  const auto follow = std::min(size, static_cast<std::size_t>(options_.scale_tracks));
  follow_.assign(follow, {});
  follow_depth_.assign(follow, 0);
  track_count_ = 0;
  follow_count_ = 0;
}

void CameraMotionEstimator::forget() {
  follow_count_ = 0;
  track_count_ = 0;
}

std::array<double, 2> CameraMotionEstimator::normalise(double u, double v) const {
  double x = 0, y = 0;
  // Beyond the lens model's fold (far outside the calibrated field) the distorted ray is the best
  // there is; its track then most likely ends as an outlier.
  if (!geometry_.normalised(u, v, x, y))
    return {(u - geometry_.cx) / geometry_.fx, (v - geometry_.cy) / geometry_.fy};
  return {x, y};
}

CameraMotion CameraMotionEstimator::estimate(std::span<const FeatureTrack> tracks,
                                             std::span<const std::array<float, 2>> followed) {
  const MotionOptions& o = options_;
  CameraMotion result;
  const int n = static_cast<int>(std::min(tracks.size(), x1_.size()));
  track_count_ = static_cast<std::size_t>(n);
  // The points followed into this frame, consumed below; new ones are chosen at the end.
  const std::size_t previous_follow = followed.size() == follow_count_ ? follow_count_ : 0;
  follow_count_ = 0;
  for (int i = 0; i < n; ++i) {
    const auto a = normalise(tracks[i].previous_u, tracks[i].previous_v);
    const auto b = normalise(tracks[i].u, tracks[i].v);
    x1_[i] = a[0];
    y1_[i] = a[1];
    x2_[i] = b[0];
    y2_[i] = b[1];
    order_[i] = i;
    inlier_[i] = 0;
  }
  if (n < std::max(5, o.min_inliers)) return result;

  // MSAC cost over Sampson distances in pixels (focal length times the normalised distance).
  const double threshold = o.essential_inlier_px / focal_;
  const double threshold_squared = threshold * threshold;
  // Stops early (flags and count then incomplete) once the cost reaches `limit`: most hypotheses
  // of a sample are wrong, and a wrong one is out after a few outliers. The distances of a block
  // of tracks at a time (a loop the compiler vectorises), then their sum in track order, the
  // limit tested after each block: the same cost as one track at a time, where it is below the
  // limit.
  constexpr double kNoLimit = std::numeric_limits<double>::infinity();
  constexpr int kBlock = 16;
  const auto score = [&](const Matrix3& e, std::uint8_t* flags, int& count, double limit) {
    double cost = 0;
    count = 0;
    std::array<double, kBlock> distances;
    for (int start = 0; start < n && cost < limit; start += kBlock) {
      const int size = std::min(kBlock, n - start);
      for (int k = 0; k < size; ++k) {
        const int i = start + k;
        distances[k] = sampson_squared(e, x1_[i], y1_[i], x2_[i], y2_[i]);
      }
      for (int k = 0; k < size; ++k) {
        const double d = distances[k];
        const bool inlier = d < threshold_squared;
        flags[start + k] = inlier ? 1 : 0;
        count += inlier ? 1 : 0;
        cost += inlier ? d : threshold_squared;
      }
    }
    return cost;
  };

  Random random{kRansacSeed};
  Matrix3 best_e;
  double best_cost = 0;
  int best_count = 0;
  bool found = false;
  int iterations_needed = o.essential_ransac_iterations;
  std::array<std::array<double, 2>, 5> sample_previous, sample_current;
  std::array<std::array<double, 9>, 10> solutions;
  for (int iteration = 0; iteration < iterations_needed; ++iteration) {
    for (int k = 0; k < 5; ++k) {
      std::swap(order_[k], order_[k + random.below(n - k)]);
      const int i = order_[k];
      sample_previous[k] = {x1_[i], y1_[i]};
      sample_current[k] = {x2_[i], y2_[i]};
    }
    const int count = five_point_essentials(sample_previous, sample_current, solutions);
    for (int s = 0; s < count; ++s) {
      const Matrix3 e =
          Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(solutions[s].data());
      int inliers = 0;
      const double cost = score(e, candidate_.data(), inliers, found ? best_cost : kNoLimit);
      if (found && cost >= best_cost) continue;
      found = true;
      best_cost = cost;
      best_count = inliers;
      best_e = e;
      std::copy(candidate_.begin(), candidate_.begin() + n, inlier_.begin());
      // Stop once a sample of all inliers has been drawn with the wanted confidence.
      const double all_inliers = std::pow(static_cast<double>(inliers) / n, 5);
      if (all_inliers >= 1.0) {
        iterations_needed = std::min(iterations_needed, iteration + 1);
      } else if (all_inliers > 0) {
        const double needed = std::log(1 - kRansacConfidence) / std::log(1 - all_inliers) + 1;
        if (needed < iterations_needed) iterations_needed = static_cast<int>(needed);
      }
    }
  }
  if (!found || best_count < 5) return result;

  // Linear refit on the inliers (eight-point, projected onto the essential matrices), kept when
  // its cost is lower; repeated while it improves.
  for (int round = 0; round < 2 && best_count >= 8; ++round) {
    Eigen::Matrix<double, 9, 9> normal = Eigen::Matrix<double, 9, 9>::Zero();
    for (int i = 0; i < n; ++i) {
      if (!inlier_[i]) continue;
      const auto row = epipolar_row(x1_[i], y1_[i], x2_[i], y2_[i]);
      normal.noalias() += row * row.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> solver(normal);
    if (solver.info() != Eigen::Success) break;
    const Eigen::Matrix<double, 9, 1> v = solver.eigenvectors().col(0);
    const Matrix3 e = project_to_essential(
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data()));
    if (!e.allFinite()) break;
    int inliers = 0;
    const double cost = score(e, candidate_.data(), inliers, best_cost);
    if (cost >= best_cost) break;
    best_cost = cost;
    best_count = inliers;
    best_e = e;
    std::copy(candidate_.begin(), candidate_.begin() + n, inlier_.begin());
  }
  result.inliers = best_count;

  // The four decompositions (R, +-t): the one that puts the inliers in front of both cameras.
  Matrix3 u, v;
  if (!essential_decomposition(best_e, u, v)) return result;
  Matrix3 w;
  w << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const std::array<Matrix3, 2> rotations{u * w * v.transpose(), u * w.transpose() * v.transpose()};
  Matrix3 rotation = rotations[0];
  Vector3 translation = u.col(2);
  int best_front = -1;
  for (const Matrix3& r : rotations) {
    for (const double sign : {1.0, -1.0}) {
      const Vector3 t = sign * u.col(2);
      int front = 0;
      for (int i = 0; i < n; ++i) {
        double d1 = 0, d2 = 0;
        if (inlier_[i] && triangulate_depths(r, t, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
            d1 > 0 && d2 > 0) {
          ++front;
        }
      }
      if (front > best_front) {
        best_front = front;
        rotation = r;
        translation = t;
      }
    }
  }
  // Refined on the image error; the inliers are those of the refined motion.
  refine_motion(x1_.data(), y1_.data(), x2_.data(), y2_.data(), inlier_.data(), n, rotation,
                translation);
  best_e = skew(translation) * rotation;
  score(best_e, inlier_.data(), best_count, kNoLimit);
  result.inliers = best_count;
  best_front = 0;
  for (int i = 0; i < n; ++i) {
    double d1 = 0, d2 = 0;
    if (inlier_[i] &&
        triangulate_depths(rotation, translation, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
        d1 > 0 && d2 > 0) {
      ++best_front;
    }
  }
  result.rotation = rotation;
  result.translation = translation;

  // Rotation alone (Procrustes on the inliers' rays): when it explains the image motion to within
  // essential_min_parallax_px, the translation's direction is not determined by the image.
  Matrix3 correlation = Matrix3::Zero();
  for (int i = 0; i < n; ++i) {
    if (!inlier_[i]) continue;
    correlation.noalias() += Vector3(x2_[i], y2_[i], 1).normalized() *
                             Vector3(x1_[i], y1_[i], 1).normalized().transpose();
  }
  const Eigen::JacobiSVD<Matrix3> svd(correlation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Matrix3 fix = Matrix3::Identity();
  fix(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
  const Matrix3 rotation_only = svd.matrixU() * fix * svd.matrixV().transpose();
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (!inlier_[i]) continue;
    const Vector3 p = rotation_only * Vector3(x1_[i], y1_[i], 1);
    residual_[m++] = p(2) > 0 ? focal_ * std::hypot(p(0) / p(2) - x2_[i], p(1) / p(2) - y2_[i])
                              : std::numeric_limits<double>::infinity();
  }
  std::nth_element(residual_.begin(), residual_.begin() + m / 2, residual_.begin() + m);
  const double parallax_px = residual_[m / 2];

  // Cheirality must hold for nearly all inliers: with noise and no parallax, depths take either
  // sign and the decomposition is a guess.
  result.valid = best_count >= o.min_inliers && 4 * best_front >= 3 * best_count &&
                 parallax_px >= o.essential_min_parallax_px;
  if (!result.valid) return result;

  // Relative scale: the points followed from the previous frame, at depth follow_depth_ (units
  // of the previous |t|) in it; their depth from this pair is in units of this |t|.
  int ratios = 0;
  for (std::size_t k = 0; k < previous_follow; ++k) {
    if (!std::isfinite(followed[k][0]) || !std::isfinite(followed[k][1])) continue;
    const auto a = normalise(follow_[k][0], follow_[k][1]);
    const auto b = normalise(followed[k][0], followed[k][1]);
    if (!(sampson_squared(best_e, a[0], a[1], b[0], b[1]) < threshold_squared)) continue;
    double d1 = 0, d2 = 0;
    if (!triangulate_depths(rotation, translation, a[0], a[1], b[0], b[1], d1, d2) || !(d1 > 0) ||
        !(d2 > 0)) {
      continue;
    }
    residual_[ratios++] = follow_depth_[k] / d1;
  }
  if (ratios >= 5) {
    std::nth_element(residual_.begin(), residual_.begin() + ratios / 2, residual_.begin() + ratios);
    result.relative_scale = residual_[ratios / 2];
  }

  // New points to follow: inliers in front of both cameras, spread over the list.
  int front = 0;
  for (int i = 0; i < n; ++i) {
    double d1 = 0, d2 = 0;
    if (inlier_[i] &&
        triangulate_depths(rotation, translation, x1_[i], y1_[i], x2_[i], y2_[i], d1, d2) &&
        d1 > 0 && d2 > 0) {
      order_[front] = i;
      residual_[front] = d2;
      ++front;
    }
  }
  const int wanted = std::min(front, static_cast<int>(follow_.size()));
  for (int k = 0; k < wanted; ++k) {
    const int j = static_cast<int>(static_cast<long long>(k) * front / wanted);
    follow_[k] = {tracks[order_[j]].u, tracks[order_[j]].v};
    follow_depth_[k] = residual_[j];
  }
  follow_count_ = static_cast<std::size_t>(wanted);
  return result;
}

}  // namespace laserline::pipeline
