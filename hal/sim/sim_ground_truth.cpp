// The simulated scene's exact answer per frame: where the laser sheet's centre meets the surface
// along each line of a family (the renderer's own or any other), its depth and the width of the
// line as rendered.
#include <algorithm>
#include <array>
#include <cmath>

#include "hal/sim/sim_lines.hpp"
#include "hal/sim/sim_render.hpp"
#include "hal/sim/sim_scene.hpp"

namespace laserline::hal {

using namespace sim;

namespace {

constexpr float kEdgeRows = 1.5f;  // truth is NaN when the centre is within 1.5 px of the border

}  // namespace

void SimScene::ground_truth(std::uint64_t sequence, bool laser_on, SimGroundTruth& truth) const {
  ground_truth(sequence, laser_on, lines_, truth);
}

void SimScene::ground_truth(std::uint64_t sequence, bool laser_on, const SimLineFamily& lines,
                            SimGroundTruth& truth) const {
  const int width = options_.calibration.camera.width;
  const int height = options_.calibration.camera.height;
  const auto count = static_cast<std::size_t>(lines.count);
  truth.lines = lines;
  truth.position.resize(count);
  truth.depth_m.resize(count);
  truth.width_px.resize(count);
  const Pose pose = pose_at(sequence);
  const double time = static_cast<double>(sequence) / options_.frame_rate_hz;
  const FrameGeometry g = make_geometry(options_, pose.r, pose.t, options_.object_speed_m_s * time);
  const bool laser = laser_on && options_.laser_peak > 0;
  const float* relief = relief_.empty() ? nullptr : relief_.data();
  // The centre must lie 1.5 px inside the frame along each image axis the line crosses.
  const std::array<float, 2> last{static_cast<float>(width - 1), static_cast<float>(height - 1)};
  // Along the renderer's own lines the profile's sigma is the line's; along others it is as the
  // renderer draws it: each pixel's light is a Gaussian in p - c(l), its position p along the
  // own lines less the centre c, interpolated between own lines l. Along a line of direction d
  // that argument changes at d . along - c'(l) d . line_step, and the sigma by 1 / that rate.
  const bool own = lines.origin == lines_.origin && lines.line_step == lines_.line_step &&
                   lines.along == lines_.along;
  auto rendered_sigma = [&](double x, double y, double z) {
    const double sigma = line_sigma(options_, lines_, z);
    if (own) return sigma;
    const auto [l, p] = lines_.to_family(x, y);
    (void)p;
    const double k0 = std::floor(l);
    LineHit h0, h1;
    if (k0 >= 0 && k0 + 1 < lines_.count) {
      h0 = solve_line(g, lines_, k0, relief, options_.relief_height_m);
      h1 = solve_line(g, lines_, k0 + 1, relief, options_.relief_height_m);
    }
    // The renderer holds the nearer line's centre where the other is not lit: no slope.
    const double slope = h0.hit && h1.hit ? h1.position - h0.position : 0.0;
    const double rate =
        lines.along[0] * lines_.along[0] + lines.along[1] * lines_.along[1] -
        slope * (lines.along[0] * lines_.line_step[0] + lines.along[1] * lines_.line_step[1]);
    return sigma / std::max(std::abs(rate), 1e-6);
  };
  for (int k = 0; k < lines.count; ++k) {
    const LineHit line =
        laser ? solve_line(g, lines, k, relief, options_.relief_height_m) : LineHit{};
    // The same float the renderer centres the profile on.
    const float position = static_cast<float>(line.position);
    bool inside = line.hit;
    const auto image = lines.to_image(k, position);
    for (int axis = 0; axis < 2 && inside; ++axis) {
      const auto at = static_cast<float>(image[axis]);
      const float edge = lines.along[axis] != 0 ? kEdgeRows : 0.0f;
      inside = at >= edge && at <= last[axis] - edge;
    }
    if (!inside) {
      truth.position[k] = truth.depth_m[k] = truth.width_px[k] = kNaN;
      continue;
    }
    truth.position[k] = position;
    truth.depth_m[k] = static_cast<float>(line.z);
    truth.width_px[k] = static_cast<float>(rendered_sigma(image[0], image[1], line.z));
  }
}

}  // namespace laserline::hal
