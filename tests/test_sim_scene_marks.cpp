// The simulator's bright marks on the surface: their albedo, density and places.
// Each checks the renderer against a computation made here or in sim_scene_reference.hpp from the
// options as sim_scene.hpp documents them, never against the renderer's own intermediate numbers.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hal/sim/sim_scene.hpp"
#include "sim_scene_reference.hpp"

namespace laserline::hal {
namespace {

using namespace sim_reference;

// ---- Bright marks ----------------------------------------------------------------------------

TEST(SimSceneMarks, MarksOfTheirAlbedoAppearAtTheRequestedDensityAndNowhereElse) {
  // A camera seeing the surface square on at exactly one texel (texture_scale_m / 4 = 2.5 mm) a
  // pixel, pixel centres on texel centres: each pixel is one texel's albedo times the ambient
  // light. 1024 x 1024 pixels are 2.56 m x 2.56 m of surface.
  SimSceneOptions o = still_options();
  o.calibration.camera.width = o.calibration.camera.height = 1024;
  o.calibration.camera.fx = o.calibration.camera.fy = 480;  // 1.2 m / 480 = 2.5 mm a pixel
  o.calibration.camera.cx = o.calibration.camera.cy = 512;
  o.noise_sigma = 0;
  o.ambient = 80;
  o.texture_contrast = 0.5;  // albedo at most 1.5 (120), marks at least 0.6 * 3 (144)
  SimScene plain(o);
  SimSceneOptions zero = o;
  zero.marks_albedo = 7;
  SimScene no_marks(zero);
  const Image before = render(plain, 0, false);
  ASSERT_EQ(before.data, render(no_marks, 0, false).data);  // zero marks: bit for bit as before
  o.marks_per_m2 = 50;
  SimScene marked(o);
  const Image after = render(marked, 0, false);
  const int w = after.width, h = after.height;
  const double pixel_m = 1.2 / 480;

  // Mark pixels: changed by more than the 1 grey level that float rounding of the texel
  // coordinates can move a neighbour. Their grey is ambient * marks_albedo * [0.6, 1].
  std::vector<int> label(after.data.size(), -1);
  auto mark = [&](int u, int v) {
    const std::size_t i = static_cast<std::size_t>(v) * w + u;
    return after.data[i] - before.data[i] >= 2;
  };
  const double lo = o.ambient * o.marks_albedo * 0.6, hi = o.ambient * o.marks_albedo;
  int changed = 0;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * w + u;
      if (mark(u, v)) {
        ++changed;
        ASSERT_GE(after.data[i], lo - 1) << u << ", " << v;
        ASSERT_LE(after.data[i], hi + 1) << u << ", " << v;
        continue;
      }
      // Elsewhere the texture is as it was (next to a mark to within that 1 level).
      bool beside = false;
      for (int dv = -1; dv <= 1; ++dv) {
        for (int du = -1; du <= 1; ++du) {
          const int uu = u + du, vv = v + dv;
          beside = beside || (uu >= 0 && vv >= 0 && uu < w && vv < h && mark(uu, vv));
        }
      }
      ASSERT_LE(std::abs(after.data[i] - before.data[i]), beside ? 1 : 0) << u << ", " << v;
    }
  }

  // Marks are the 8-connected pieces of mark pixels; those touching the frame's edge may be
  // parts of marks and are not counted. Expected: marks_per_m2 times the area, less the marks
  // cut by the edge (those within a mark's size, some 3 cm, of it: about 4 * 2.56 * 0.03 / 6.55,
  // 5 %) and those merged with another (their area is about 1 % of the surface): between 85 %
  // and 100 %.
  int marks = 0, single_valued = 0, longest = 0;
  int darkest = 255, brightest = 0;
  for (int v0 = 0; v0 < h; ++v0) {
    for (int u0 = 0; u0 < w; ++u0) {
      if (!mark(u0, v0) || label[static_cast<std::size_t>(v0) * w + u0] >= 0) continue;
      std::vector<std::pair<int, int>> stack{{u0, v0}}, piece;
      label[static_cast<std::size_t>(v0) * w + u0] = 1;
      bool edge = false;
      while (!stack.empty()) {
        const auto [u, v] = stack.back();
        stack.pop_back();
        piece.push_back({u, v});
        edge = edge || u == 0 || v == 0 || u == w - 1 || v == h - 1;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= w || vv >= h || !mark(uu, vv)) continue;
            int& l = label[static_cast<std::size_t>(vv) * w + uu];
            if (l < 0) {
              l = 1;
              stack.push_back({uu, vv});
            }
          }
        }
      }
      if (edge) continue;
      ++marks;
      const int grey = after.at(piece[0].first, piece[0].second);
      bool one_value = true;
      int umin = w, umax = 0, vmin = h, vmax = 0;
      for (const auto& [u, v] : piece) {
        one_value = one_value && after.at(u, v) == grey;
        umin = std::min(umin, u), umax = std::max(umax, u);
        vmin = std::min(vmin, v), vmax = std::max(vmax, v);
      }
      if (!one_value) continue;  // overlapping marks
      ++single_valued;
      darkest = std::min(darkest, grey);
      brightest = std::max(brightest, grey);
      longest = std::max(longest, std::max(umax - umin, vmax - vmin) + 1);
    }
  }
  const double area = w * pixel_m * h * pixel_m;
  const double expected = o.marks_per_m2 * area;
  std::printf(
      "  %d marks inside the frame (%.0f expected on %.2f m^2), %d of one albedo: grey %d to %d, "
      "longest %d px; %.2f %% of the surface\n",
      marks, expected, area, single_valued, darkest, brightest, longest, 100.0 * changed / (w * h));
  EXPECT_GE(marks, 0.85 * expected);
  EXPECT_LE(marks, expected);
  EXPECT_GE(single_valued, 0.9 * marks);
  // Albedos spread over marks_albedo * [0.6, 1]: with some 300 marks the extremes are near.
  EXPECT_LE(darkest, lo + 0.04 * (hi - lo));
  EXPECT_GE(brightest, hi - 0.04 * (hi - lo));
  // No mark is longer than the longest stroke, 8 cm (32 px) and its width.
  EXPECT_LE(longest, 0.08 / pixel_m + 4);
  EXPECT_GT(longest, 0.05 / pixel_m);
}

}  // namespace
}  // namespace laserline::hal
