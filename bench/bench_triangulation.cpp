// Triangulation of one frame's points (pipeline/triangulation.hpp) at 2048x1536: one point per
// column on the laser line, with a distortion-free lens (ray/plane only) and with a strongly
// distorting one (Newton inversion of OpenCV's model per point).
//   triangulation: Triangulator::fill()
//   naive:         cv::undistortPoints (its default fixed-point iteration, less exact) + the same
//                  ray/plane intersection, as a reference measured in the same run
// Run: build/default/bench/laserline_bench --benchmark_filter=triangulation
#include <benchmark/benchmark.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/triangulation.hpp"

namespace {

laserline::pipeline::ScannerGeometry geometry(bool distorted) {
  laserline::pipeline::ScannerGeometry g;
  g.width = 2048;
  g.height = 1536;
  g.fx = g.fy = 2240;
  g.cx = 1023.5;
  g.cy = 767.5;
  if (distorted) g.distortion = {-0.28, 0.12, 0.0012, -0.0008, -0.03};
  return g;
}

// A laser line across the image, one point per column, all accepted.
laserline::pipeline::Profile line_profile(const laserline::pipeline::ScannerGeometry& g) {
  laserline::pipeline::Profile profile(static_cast<std::size_t>(g.width));
  for (int u = 0; u < g.width; ++u)
    profile.add({u, static_cast<float>(600.0 + 0.05 * u), 12.0f, -1, true});
  return profile;
}

void BM_triangulation(benchmark::State& state) {
  const auto g = geometry(state.range(0) != 0);
  const laserline::pipeline::Triangulator triangulator(g);
  laserline::pipeline::Profile profile = line_profile(g);
  for (auto _ : state) {
    triangulator.fill(profile);
    benchmark::DoNotOptimize(profile.points().data());
  }
  state.SetItemsProcessed(state.iterations() * g.width);
}
BENCHMARK(BM_triangulation)->ArgName("distorted")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_naive_triangulation(benchmark::State& state) {
  const auto g = geometry(state.range(0) != 0);
  laserline::pipeline::Profile profile = line_profile(g);
  const cv::Matx33d k(g.fx, 0, g.cx, 0, g.fy, g.cy, 0, 0, 1);
  const std::vector<double> distortion(g.distortion.begin(), g.distortion.end());
  std::vector<cv::Point2f> pixels(profile.size()), normalised;
  for (auto _ : state) {
    for (std::size_t i = 0; i < profile.size(); ++i)
      pixels[i] = {static_cast<float>(profile.points()[i].u), profile.points()[i].v};
    cv::undistortPoints(pixels, normalised, k, distortion);
    auto points = profile.mutable_points();
    const double a = g.laser_plane[0], b = g.laser_plane[1], c = g.laser_plane[2],
                 e = g.laser_plane[3];
    for (std::size_t i = 0; i < normalised.size(); ++i) {
      const double z = -e / (a * normalised[i].x + b * normalised[i].y + c);
      points[i].xyz = {static_cast<float>(normalised[i].x * z),
                       static_cast<float>(normalised[i].y * z), static_cast<float>(z)};
    }
    benchmark::DoNotOptimize(points.data());
  }
  state.SetItemsProcessed(state.iterations() * g.width);
}
BENCHMARK(BM_naive_triangulation)
    ->ArgName("distorted")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
