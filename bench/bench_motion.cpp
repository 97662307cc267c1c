// Frame-to-frame homography estimation on simulated 2048x1536 mono8 frames of a swaying camera:
//   frontend: MotionEstimator::update() (pipeline/motion.hpp): builds the pyramid, tracks the
//             previous frame's features, runs RANSAC and the refit, finds the next features
//   naive:    the same stages from stock OpenCV calls (buildOpticalFlowPyramid,
//             goodFeaturesToTrack at the same level, calcOpticalFlowPyrLK, findHomography),
//             single thread, as a reference measured in the same run
// Run: build/default/bench/laserline_bench --benchmark_filter=homography
#include <benchmark/benchmark.h>

#include <cstdint>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <utility>
#include <vector>

#include "bench_scenes.hpp"
#include "hal/sim/sim_scene.hpp"
#include "pipeline/motion.hpp"

namespace {

// Two frames a few apart, so that the camera has visibly moved; the laser is on.
std::vector<std::vector<std::uint8_t>> sim_frames(int width, int height) {
  laserline::hal::SimScene scene(sim_options(width, height));
  std::vector<std::vector<std::uint8_t>> frames(2,
                                                std::vector<std::uint8_t>(scene.format().bytes()));
  scene.render(10, true, frames[0]);
  scene.render(13, true, frames[1]);
  return frames;
}

void BM_frontend_homography_estimation(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const std::vector<std::vector<std::uint8_t>> frames = sim_frames(width, height);
  laserline::pipeline::MotionEstimator estimator;
  estimator.reset(width, height);
  std::size_t next = 0;
  const auto feed = [&] {
    const laserline::pipeline::ImageView view{frames[next].data(), width, height, width};
    next = 1 - next;
    return estimator.update(view);
  };
  feed();
  laserline::pipeline::MotionEstimate estimate;
  std::int64_t valid = 0;
  for (auto _ : state) {
    estimate = feed();
    valid += estimate.valid ? 1 : 0;
    benchmark::DoNotOptimize(estimate);
  }
  state.counters["valid"] = static_cast<double>(valid) / static_cast<double>(state.iterations());
  state.counters["inliers"] = estimate.inliers;
  state.counters["tracked"] = estimate.tracked;
  state.counters["rejected_on_laser"] = estimate.rejected_on_laser;
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_frontend_homography_estimation)->Args({2048, 1536})->Unit(benchmark::kMillisecond);

// Reference: the stock OpenCV composition one writes first, with the same bounds (up to 192
// features found at pyramid level 2, 9x9 window, 4 levels, 10 iterations, RANSAC at 1 px and
// 200 iterations). No laser filter.
void BM_naive_homography_estimation(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  std::vector<std::vector<std::uint8_t>> frames = sim_frames(width, height);
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const cv::Size window(9, 9);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 10, 0.01);
  std::vector<cv::Mat> previous_pyramid, pyramid;
  std::vector<cv::Point2f> previous_points, points, tracked, from, to;
  std::vector<std::uint8_t> status, mask;
  std::vector<float> error;
  std::size_t next = 0;
  std::int64_t valid = 0;
  int inliers = 0;
  for (auto _ : state) {
    const cv::Mat frame(height, width, CV_8UC1, frames[next].data());
    next = 1 - next;
    cv::buildOpticalFlowPyramid(frame, pyramid, window, 3, false);
    if (!previous_points.empty()) {
      cv::calcOpticalFlowPyrLK(previous_pyramid, pyramid, previous_points, tracked, status, error,
                               window, 3, criteria);
      from.clear();
      to.clear();
      for (std::size_t i = 0; i < status.size(); ++i) {
        if (!status[i]) continue;
        from.push_back(previous_points[i]);
        to.push_back(tracked[i]);
      }
      if (from.size() >= 12) {
        const cv::Mat h = cv::findHomography(from, to, cv::RANSAC, 1.0, mask, 200, 0.999);
        inliers = cv::countNonZero(mask);
        valid += h.empty() ? 0 : 1;
      }
    }
    // Features at level 2 (a quarter of the size), at most one per 16 level-2 pixels apart.
    cv::goodFeaturesToTrack(pyramid[2], points, 192, 0.01, 16, cv::noArray(), 3, false);
    for (cv::Point2f& p : points)
      p = p * 4.0f + cv::Point2f(1.5f, 1.5f);
    std::swap(previous_pyramid, pyramid);
    std::swap(previous_points, points);
  }
  cv::setNumThreads(threads);
  state.counters["valid"] = static_cast<double>(valid) / static_cast<double>(state.iterations());
  state.counters["inliers"] = inliers;
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_naive_homography_estimation)->Args({2048, 1536})->Unit(benchmark::kMillisecond);

}  // namespace
