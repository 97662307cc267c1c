// The five-point solver (pipeline/five_point.hpp) on its own, beside OpenCV's
// (cv::findEssentialMat, cv::recoverPose) on synthetic correspondences with exact ground truth:
// on five points both return the same essential matrices, with and without noise; over many
// noisy points with outliers, a RANSAC over either solver recovers the same motion.
#include "pipeline/five_point.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <vector>

namespace laserline::pipeline {
namespace {

// Normalised image coordinates (focal length 1) of points seen by two cameras, X_2 = R X_1 + t.
struct Correspondences {
  cv::Matx33d r;
  cv::Vec3d t;  // unit length
  std::vector<cv::Point2d> first, second;
};

// The focal length, in pixels, the noise is given for.
constexpr double kFocalPx = 1500;

// `count` points 1.5 .. 4 m in front of the first camera within a 50 degree field, the second
// camera turned by up to 6 degrees and moved by 0.1 .. 0.5 m; `noise_px` of Gaussian noise on
// every coordinate and the last `outliers` of the second camera's points moved anywhere.
Correspondences make_correspondences(cv::RNG& rng, int count, double noise_px, int outliers = 0) {
  Correspondences c;
  cv::Mat r;
  cv::Rodrigues(cv::Vec3d(rng.uniform(-6.0, 6.0), rng.uniform(-6.0, 6.0), rng.uniform(-6.0, 6.0)) *
                    (CV_PI / 180.0),
                r);
  c.r = cv::Matx33d(r);
  const cv::Vec3d direction(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
  c.t = direction / cv::norm(direction);
  const cv::Vec3d moved = c.t * rng.uniform(0.1, 0.5);
  const double noise = noise_px / kFocalPx;
  while (static_cast<int>(c.first.size()) < count) {
    const double z = rng.uniform(1.5, 4.0);
    const cv::Vec3d p(rng.uniform(-0.45, 0.45) * z, rng.uniform(-0.45, 0.45) * z, z);
    const cv::Vec3d q = c.r * p + moved;
    if (q[2] < 0.5) continue;
    c.first.emplace_back(p[0] / p[2] + rng.gaussian(noise), p[1] / p[2] + rng.gaussian(noise));
    c.second.emplace_back(q[0] / q[2] + rng.gaussian(noise), q[1] / q[2] + rng.gaussian(noise));
  }
  for (int i = count - outliers; i < count; ++i)
    c.second[i] = {rng.uniform(-0.45, 0.45), rng.uniform(-0.45, 0.45)};
  return c;
}

// Essential matrices of unit norm; a solution and its negative are the same.
double distance_up_to_sign(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d an = a * (1.0 / cv::norm(a)), bn = b * (1.0 / cv::norm(b));
  return std::min(cv::norm(an - bn), cv::norm(an + bn));
}

std::vector<cv::Matx33d> ours(const Correspondences& c, const std::array<int, 5>& sample) {
  std::array<std::array<double, 2>, 5> previous, current;
  for (int k = 0; k < 5; ++k) {
    previous[k] = {c.first[sample[k]].x, c.first[sample[k]].y};
    current[k] = {c.second[sample[k]].x, c.second[sample[k]].y};
  }
  std::array<std::array<double, 9>, 10> solutions;
  const int count = five_point_essentials(previous, current, solutions);
  std::vector<cv::Matx33d> out;
  for (int s = 0; s < count; ++s)
    out.emplace_back(solutions[s].data());
  return out;
}

// OpenCV's five-point solver on exactly five points returns all its solutions, stacked.
std::vector<cv::Matx33d> opencv(const Correspondences& c) {
  const cv::Mat stacked =
      cv::findEssentialMat(c.first, c.second, 1.0, cv::Point2d(0, 0), cv::RANSAC);
  std::vector<cv::Matx33d> out;
  for (int s = 0; s + 3 <= stacked.rows; s += 3)
    out.emplace_back(cv::Mat(stacked.rowRange(s, s + 3)));
  return out;
}

// Largest distance from a solution of `a` to the nearest solution of `b`.
double farthest_unmatched(const std::vector<cv::Matx33d>& a, const std::vector<cv::Matx33d>& b) {
  double farthest = 0;
  for (const cv::Matx33d& e : a) {
    double nearest = 1e9;
    for (const cv::Matx33d& f : b)
      nearest = std::min(nearest, distance_up_to_sign(e, f));
    farthest = std::max(farthest, nearest);
  }
  return farthest;
}

cv::Matx33d true_essential(const Correspondences& c) {
  const cv::Matx33d tx(0, -c.t[2], c.t[1], c.t[2], 0, -c.t[0], -c.t[1], c.t[0], 0);
  return tx * c.r;
}

// Angles by atan2 of sine and cosine, precise for small ones as acos is not.
double rotation_error_deg(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a.t() * b;
  const cv::Vec3d sine_axis(d(2, 1) - d(1, 2), d(0, 2) - d(2, 0), d(1, 0) - d(0, 1));
  return std::atan2(0.5 * cv::norm(sine_axis), 0.5 * (cv::trace(d) - 1.0)) * 180.0 / CV_PI;
}

double direction_error_deg(const cv::Vec3d& a, const cv::Vec3d& b) {
  return std::atan2(cv::norm(a.cross(b)), a.dot(b)) * 180.0 / CV_PI;
}

// R and t of E by cv::recoverPose (cheirality over all the points it is given).
struct Motion {
  cv::Matx33d r;
  cv::Vec3d t;
};
Motion recover(const cv::Matx33d& e, const Correspondences& c) {
  cv::Mat r, t;
  cv::recoverPose(cv::Mat(e), c.first, c.second, r, t, 1.0, cv::Point2d(0, 0));
  return {cv::Matx33d(r), cv::Vec3d(t)};
}

void expect_same_solutions_as_opencv(double noise_px, int trials) {
  cv::RNG rng(11);
  int compared = 0;
  for (int trial = 0; trial < trials; ++trial) {
    const Correspondences c = make_correspondences(rng, 5, noise_px);
    const std::vector<cv::Matx33d> mine = ours(c, {0, 1, 2, 3, 4});
    const std::vector<cv::Matx33d> theirs = opencv(c);
    ASSERT_GE(mine.size(), 1u) << "trial " << trial;
    ASSERT_GE(theirs.size(), 1u) << "trial " << trial;
    EXPECT_EQ(mine.size(), theirs.size()) << "trial " << trial;
    EXPECT_LT(farthest_unmatched(mine, theirs), 1e-5) << "trial " << trial;
    EXPECT_LT(farthest_unmatched(theirs, mine), 1e-5) << "trial " << trial;
    if (noise_px == 0) {
      EXPECT_LT(farthest_unmatched({true_essential(c)}, mine), 1e-8) << "trial " << trial;
    }
    ++compared;
  }
  EXPECT_EQ(compared, trials);
}

TEST(FivePointAgainstOpenCv, SameEssentialMatricesOnFiveExactPoints) {
  expect_same_solutions_as_opencv(0.0, 40);
}

TEST(FivePointAgainstOpenCv, SameEssentialMatricesOnFiveNoisyPoints) {
  expect_same_solutions_as_opencv(0.5, 40);
}

// A RANSAC of bounded samples over our solver, the hypothesis with the most inliers (Sampson
// distance), decomposed by cv::recoverPose; beside cv::findEssentialMat's own RANSAC.
Motion ransac_with_ours(const Correspondences& c, double threshold) {
  cv::RNG rng(3);
  const int n = static_cast<int>(c.first.size());
  cv::Matx33d best;
  int best_inliers = -1;
  for (int iteration = 0; iteration < 300; ++iteration) {
    std::array<int, 5> sample;
    for (int k = 0; k < 5; ++k) {
      do {
        sample[k] = rng.uniform(0, n);
      } while (std::find(sample.begin(), sample.begin() + k, sample[k]) != sample.begin() + k);
    }
    for (const cv::Matx33d& e : ours(c, sample)) {
      int inliers = 0;
      for (int i = 0; i < n; ++i) {
        const cv::Vec3d a(c.first[i].x, c.first[i].y, 1), b(c.second[i].x, c.second[i].y, 1);
        const cv::Vec3d ea = e * a, etb = e.t() * b;
        const double residual = b.dot(ea);
        const double denominator =
            ea[0] * ea[0] + ea[1] * ea[1] + etb[0] * etb[0] + etb[1] * etb[1];
        inliers += residual * residual < threshold * threshold * denominator ? 1 : 0;
      }
      if (inliers > best_inliers) {
        best_inliers = inliers;
        best = e;
      }
    }
  }
  return recover(best, c);
}

// Both within `rotation_deg` and `direction_deg` of the truth on each of ten scenes, and ours no
// worse than OpenCV's over all of them (sums of the errors, with a margin for the random draws).
void expect_same_motion_as_opencv(double noise_px, int outliers, double rotation_deg,
                                  double direction_deg) {
  cv::RNG rng(5);
  double ours_sum = 0, opencv_sum = 0;
  for (int trial = 0; trial < 10; ++trial) {
    const Correspondences c = make_correspondences(rng, 150, noise_px, outliers);
    const double threshold = std::max(1.5 * noise_px, 0.5) / kFocalPx;
    const Motion mine = ransac_with_ours(c, threshold);
    const cv::Mat e_opencv = cv::findEssentialMat(c.first, c.second, 1.0, cv::Point2d(0, 0),
                                                  cv::RANSAC, 0.999, threshold);
    ASSERT_EQ(e_opencv.rows, 3) << "trial " << trial;
    const Motion theirs = recover(cv::Matx33d(e_opencv), c);
    const double mine_r = rotation_error_deg(mine.r, c.r),
                 mine_t = direction_error_deg(mine.t, c.t);
    const double theirs_r = rotation_error_deg(theirs.r, c.r);
    const double theirs_t = direction_error_deg(theirs.t, c.t);
    EXPECT_LT(mine_r, rotation_deg) << "trial " << trial;
    EXPECT_LT(mine_t, direction_deg) << "trial " << trial;
    EXPECT_LT(theirs_r, rotation_deg) << "trial " << trial;
    EXPECT_LT(theirs_t, direction_deg) << "trial " << trial;
    ours_sum += mine_r + mine_t;
    opencv_sum += theirs_r + theirs_t;
  }
  EXPECT_LE(ours_sum, 1.5 * opencv_sum + 1e-9);
}

TEST(FivePointAgainstOpenCv, SameMotionFromExactPoints) {
  expect_same_motion_as_opencv(0.0, 0, 1e-8, 1e-8);
}

TEST(FivePointAgainstOpenCv, SameMotionFromNoisyPointsWithOutliers) {
  expect_same_motion_as_opencv(0.5, 30, 0.6, 2.5);
}

}  // namespace
}  // namespace laserline::pipeline
