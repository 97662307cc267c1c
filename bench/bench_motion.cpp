// Frame-to-frame homography estimation on simulated 2048x1536 mono8 frames of a swaying camera:
//   frontend: MotionEstimator::update() (pipeline/motion.hpp): builds the pyramid, tracks the
//             previous frame's features, runs RANSAC and the refit, finds the next features
//   naive:    the same stages from stock OpenCV calls (buildOpticalFlowPyramid,
//             goodFeaturesToTrack at the same level, calcOpticalFlowPyrLK, findHomography),
//             single thread, as a reference measured in the same run
//   camera:   the same with the intrinsics (reset() with a ScannerGeometry): also the camera
//   motion,
//             five-point RANSAC, refinement and the tracks followed for the relative scale, on a
//             pier (relief, vehicle moving); essential_ransac: that stage alone on the same tracks,
//             naive_essential: cv::findEssentialMat + cv::recoverPose on them, as a reference
// Run: build/default/bench/laserline_bench --benchmark_filter='homography|camera|essential'
#include <benchmark/benchmark.h>

#include <cmath>
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

// Frames `first` and `second` of a simulated scan, the laser on.
std::vector<std::vector<std::uint8_t>> render_pair(const laserline::hal::SimSceneOptions& o,
                                                   std::uint64_t first, std::uint64_t second) {
  laserline::hal::SimScene scene(o);
  std::vector<std::vector<std::uint8_t>> frames(2,
                                                std::vector<std::uint8_t>(scene.format().bytes()));
  scene.render(first, true, frames[0]);
  scene.render(second, true, frames[1]);
  return frames;
}

// Two frames a few apart, so that the camera has visibly moved.
std::vector<std::vector<std::uint8_t>> sim_frames(int width, int height) {
  return render_pair(sim_options(width, height), 10, 13);
}

// A function that feeds the estimator the two frames in turn, returning its estimate.
auto alternating_feed(const std::vector<std::vector<std::uint8_t>>& frames, int width, int height,
                      laserline::pipeline::MotionEstimator& estimator) {
  return [&frames, width, height, &estimator, next = std::size_t{0}]() mutable {
    const laserline::pipeline::ImageView view{frames[next].data(), width, height, width};
    next = 1 - next;
    return estimator.update(view);
  };
}

void BM_frontend_homography_estimation(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const std::vector<std::vector<std::uint8_t>> frames = sim_frames(width, height);
  laserline::pipeline::MotionEstimator estimator;
  estimator.reset(width, height);
  auto feed = alternating_feed(frames, width, height, estimator);
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

// A pier: relief of 5-30 cm, the vehicle moving at 0.4 m/s, two consecutive frames.
laserline::hal::SimSceneOptions pier_options(int width, int height) {
  laserline::hal::SimSceneOptions o = sim_options(width, height);
  o.relief_height_m = 0.30;
  o.relief_min_height_m = 0.05;
  o.relief_max_slope = 0.9;
  o.vehicle_speed_m_s = 0.4;
  o.seed = 5;
  return o;
}

laserline::pipeline::ScannerGeometry geometry_of(const laserline::hal::SimSceneOptions& o) {
  laserline::pipeline::ScannerGeometry g;
  const laserline::hal::CameraIntrinsics& cam = o.calibration.camera;
  g.width = cam.width;
  g.height = cam.height;
  g.fx = cam.fx;
  g.fy = cam.fy;
  g.cx = cam.cx;
  g.cy = cam.cy;
  g.distortion = cam.distortion;
  return g;
}

std::vector<std::vector<std::uint8_t>> pier_frames(const laserline::hal::SimSceneOptions& o) {
  return render_pair(o, 10, 11);
}

void BM_frontend_camera_motion_estimation(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const laserline::hal::SimSceneOptions options = pier_options(width, height);
  const std::vector<std::vector<std::uint8_t>> frames = pier_frames(options);
  const laserline::pipeline::ScannerGeometry geometry = geometry_of(options);
  // Argument 2: 0 = homography only (no intrinsics), 1 = with the camera motion, 2 = with the
  // camera motion but no relative scale (scale_tracks = 0: no tracks followed).
  laserline::pipeline::MotionOptions motion_options;
  if (state.range(2) == 2) motion_options.scale_tracks = 0;
  laserline::pipeline::MotionEstimator estimator(motion_options);
  const bool with_camera = state.range(2) != 0;
  estimator.reset(width, height, with_camera ? &geometry : nullptr);
  auto feed = alternating_feed(frames, width, height, estimator);
  feed();
  laserline::pipeline::MotionEstimate estimate;
  std::int64_t valid = 0, scaled = 0;
  for (auto _ : state) {
    estimate = feed();
    valid += estimate.camera.valid ? 1 : 0;
    scaled += std::isfinite(estimate.camera.relative_scale) ? 1 : 0;
    benchmark::DoNotOptimize(estimate);
  }
  const auto iterations = static_cast<double>(state.iterations());
  state.counters["camera_valid"] = static_cast<double>(valid) / iterations;
  state.counters["scale_known"] = static_cast<double>(scaled) / iterations;
  state.counters["camera_inliers"] = estimate.camera.inliers;
  state.counters["tracked"] = estimate.tracked;
  state.SetBytesProcessed(state.iterations() * width * height);
}
BENCHMARK(BM_frontend_camera_motion_estimation)
    ->Args({2048, 1536, 0})
    ->Args({2048, 1536, 1})
    ->Args({2048, 1536, 2})
    ->Unit(benchmark::kMillisecond);

// The tracks of one pier frame pair, as MotionEstimator found them.
std::vector<laserline::pipeline::FeatureTrack> pier_tracks(
    const laserline::hal::SimSceneOptions& options) {
  const int width = options.calibration.camera.width, height = options.calibration.camera.height;
  const std::vector<std::vector<std::uint8_t>> frames = pier_frames(options);
  laserline::pipeline::MotionEstimator estimator;
  estimator.reset(width, height);
  for (const auto& frame : frames)
    estimator.update(laserline::pipeline::ImageView{frame.data(), width, height, width});
  return {estimator.tracks().begin(), estimator.tracks().end()};
}

// The pier tracks with the first `outlier_percent` % of them made outliers (moved anywhere).
std::vector<laserline::pipeline::FeatureTrack> pier_tracks_with_outliers(
    const laserline::hal::SimSceneOptions& options, std::int64_t outlier_percent) {
  const int width = options.calibration.camera.width, height = options.calibration.camera.height;
  std::vector<laserline::pipeline::FeatureTrack> tracks = pier_tracks(options);
  std::uint64_t random = 12345;
  for (std::size_t i = 0; i < tracks.size(); ++i) {
    if (static_cast<std::int64_t>(i * 100 / tracks.size()) >= outlier_percent) continue;
    random = random * 6364136223846793005ull + 1442695040888963407ull;
    tracks[i].u = static_cast<float>((random >> 33) % static_cast<std::uint64_t>(width));
    tracks[i].v = static_cast<float>((random >> 13) % static_cast<std::uint64_t>(height));
  }
  return tracks;
}

// Argument 2 of both essential benchmarks: percent of the tracks made outliers. At 50 %, RANSAC
// needs more samples than essential_ransac_iterations and runs them all, the worst case.
void BM_frontend_essential_ransac(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const laserline::hal::SimSceneOptions options = pier_options(width, height);
  const std::vector<laserline::pipeline::FeatureTrack> tracks =
      pier_tracks_with_outliers(options, state.range(2));
  laserline::pipeline::CameraMotionEstimator estimator;
  estimator.reset(geometry_of(options), static_cast<int>(tracks.size()));
  laserline::pipeline::CameraMotion motion;
  std::int64_t valid = 0;
  for (auto _ : state) {
    estimator.forget();
    motion = estimator.estimate(tracks, {});
    valid += motion.valid ? 1 : 0;
    benchmark::DoNotOptimize(motion);
  }
  state.counters["valid"] = static_cast<double>(valid) / static_cast<double>(state.iterations());
  state.counters["inliers"] = motion.inliers;
  state.counters["tracks"] = static_cast<double>(tracks.size());
}
BENCHMARK(BM_frontend_essential_ransac)
    ->Args({2048, 1536, 0})
    ->Args({2048, 1536, 25})
    ->Args({2048, 1536, 50})
    ->Unit(benchmark::kMillisecond);

// Reference: cv::findEssentialMat (five-point RANSAC, 1 px, 0.999) and cv::recoverPose on the
// same tracks, single thread; lens distortion is zero in the simulator, so no undistortion.
void BM_naive_essential_ransac(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0)), height = static_cast<int>(state.range(1));
  const laserline::hal::SimSceneOptions options = pier_options(width, height);
  const std::vector<laserline::pipeline::FeatureTrack> tracks =
      pier_tracks_with_outliers(options, state.range(2));
  const laserline::hal::CameraIntrinsics& cam = options.calibration.camera;
  const cv::Matx33d k(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  std::vector<cv::Point2d> from, to;
  for (const auto& t : tracks) {
    from.emplace_back(t.previous_u, t.previous_v);
    to.emplace_back(t.u, t.v);
  }
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  std::int64_t valid = 0;
  int inliers = 0;
  cv::Mat mask, r, t;
  for (auto _ : state) {
    const cv::Mat e = cv::findEssentialMat(from, to, k, cv::RANSAC, 0.999, 1.0, mask);
    if (e.rows == 3) {
      // Depths are up to ~100 times the baseline here: the default distance limit (50) would
      // reject every point.
      inliers = cv::recoverPose(e, from, to, k, r, t, 1e9, mask);
      valid += 1;
    }
    benchmark::DoNotOptimize(r);
  }
  cv::setNumThreads(threads);
  state.counters["valid"] = static_cast<double>(valid) / static_cast<double>(state.iterations());
  state.counters["inliers"] = inliers;
  state.counters["tracks"] = static_cast<double>(tracks.size());
}
BENCHMARK(BM_naive_essential_ransac)
    ->Args({2048, 1536, 0})
    ->Args({2048, 1536, 25})
    ->Args({2048, 1536, 50})
    ->Unit(benchmark::kMillisecond);

}  // namespace
