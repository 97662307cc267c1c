// Every vector kernel of pipeline/kernels/ against its scalar reference, to the bit, on every
// target Highway compiled that this CPU runs (e.g. SSSE3, SSE4, AVX2, AVX-512 and the scalar
// one on x86-64; NEON and SVE on arm64): random inputs and edge cases (widths of 0, 1, less than
// a vector, odd; extreme values).
// Over 600 lines: one unit (pipeline/kernels/), a reference comparison per kernel.
#include "pipeline/kernels/kernels.hpp"

#include <gtest/gtest.h>

#include <hwy/targets.h>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace laserline::pipeline::kernels {
namespace {

constexpr int kWidths[] = {0, 1, 3, 7, 8, 15, 16, 17, 31, 33, 63, 64, 65, 100, 272, 1001};

// Runs `body` once per target, the kernels dispatched to it. Each is compared with the scalar
// references; x86-64 compiles several targets (the CPU's best down to the baseline), arm64 NEON
// alone (pipeline/CMakeLists.txt).
template <class Body>
void for_each_target(Body body) {
  const std::vector<std::int64_t> targets = hwy::SupportedAndGeneratedTargets();
#if defined(__x86_64__)
  ASSERT_GE(targets.size(), 2u) << "only " << hwy::TargetName(targets.front());
#else
  ASSERT_GE(targets.size(), 1u);
#endif
  for (const std::int64_t target : targets) {
    hwy::SetSupportedTargetsForTest(target);
    SCOPED_TRACE(std::string("target ") + hwy::TargetName(target));
    ASSERT_STREQ(target_name(), hwy::TargetName(target));
    body();
  }
  hwy::SetSupportedTargetsForTest(0);
}

template <class T>
std::vector<T> random_values(std::mt19937& random, std::size_t n, T lo, T hi) {
  std::uniform_int_distribution<long long> pick(lo, hi);
  std::vector<T> values(n);
  for (T& value : values)
    value = static_cast<T>(pick(random));
  // Edge values first: the extremes side by side.
  for (std::size_t i = 0; i < std::min<std::size_t>(n, 4); ++i)
    values[i] = i % 2 == 0 ? hi : lo;
  return values;
}

TEST(Kernels, InterpolateRowMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(1);
    for (const int width : kWidths) {
      for (const int shift : {0, 3, 4, 5}) {
        for (const std::uint16_t fb : {0, 1, 37, 64, 127, 128}) {
          const auto a = random_values<std::uint8_t>(random, width + 1, 0, 255);
          const auto b = random_values<std::uint8_t>(random, width + 1, 0, 255);
          std::vector<std::uint16_t> got(width + 1, 7), expected(width + 1, 7);
          interpolate_row(a.data(), b.data(), fb, shift, width, got.data());
          reference::interpolate_row(a.data(), b.data(), fb, shift, width, expected.data());
          ASSERT_EQ(got, expected) << "width " << width << " shift " << shift << " fb " << fb;
        }
      }
    }
  });
}

TEST(Kernels, DifferenceRowMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(2);
    constexpr int kWarp = WarpRow::kWarpBlock;
    const int bg_width = 300, bg_height = 40;
    const auto background = random_values<std::uint8_t>(random, bg_width * bg_height, 0, 255);
    int partial_blocks = 0, whole_blocks = 0;
    for (const int width : {64, 65, 77, 95, 96, 250}) {
      for (const int shift : {0, 3, 5}) {
        const int blocks = (width + kWarp - 1) / kWarp;
        std::vector<std::int32_t> left(blocks), top(blocks), whole(blocks), offset(blocks);
        std::vector<std::int32_t> w00(blocks), w01(blocks), w10(blocks), w11(blocks);
        std::uniform_int_distribution<int> column(-40, bg_width + 10), row(-3, bg_height + 2);
        std::uniform_int_distribution<int> share(0, kFixedOne);
        int partial = 0;
        for (int j = 0; j < blocks; ++j) {
          left[j] = column(random);
          top[j] = row(random);
          const int count = std::min(kWarp, width - j * kWarp);
          whole[j] = count == kWarp && left[j] >= 0 && left[j] + kWarp <= bg_width - 1 &&
                     top[j] >= 0 && top[j] < bg_height - 1;
          partial += 1 - whole[j];
          offset[j] = whole[j] ? top[j] * bg_width + left[j] : -12345;
          const int top_share = share(random), bottom_share = kFixedOne - top_share;
          w00[j] = std::uniform_int_distribution<int>(0, top_share)(random);
          w01[j] = top_share - w00[j];
          w10[j] = std::uniform_int_distribution<int>(0, bottom_share)(random);
          w11[j] = bottom_share - w10[j];
        }
        const auto a = random_values<std::uint8_t>(random, width, 0, 255);
        const auto b = random_values<std::uint8_t>(random, width, 0, 255);
        std::vector<std::uint16_t> got(width + 1, 7), expected(width + 1, 7);
        const auto fb = static_cast<std::uint16_t>(share(random));
        WarpRow warp{
            a.data(),      b.data(),    fb,         shift,        got.data(),    background.data(),
            bg_width,      left.data(), top.data(), whole.data(), offset.data(), w00.data(),
            w01.data(),    w10.data(),  w11.data(), blocks,       width,         bg_width - 1,
            bg_height - 1, partial};
        difference_row(warp);
        warp.out = expected.data();
        reference::difference_row(warp);
        ASSERT_EQ(got, expected) << "width " << width << " shift " << shift;
        partial_blocks += partial;
        whole_blocks += blocks - partial;
      }
    }
    EXPECT_GT(partial_blocks, 5);
    EXPECT_GT(whole_blocks, 5);
  });
}

// A still camera: the frame's columns fall on the background's own, the last one on its last
// column, whose right neighbours (weight 0 there; at most a pixel beyond it) are taken as it is.
// Every pixel, the last included, is the frame less the background, on every target.
TEST(Kernels, DifferenceOfAStillFrameReachesTheLastColumn) {
  for_each_target([] {
    constexpr int kWarp = WarpRow::kWarpBlock;
    for (const int width : {64, 77, 250}) {
      const int blocks = (width + kWarp - 1) / kWarp, height = 4;
      std::vector<std::uint8_t> background(static_cast<std::size_t>(width) * height);
      for (std::size_t i = 0; i < background.size(); ++i)
        background[i] = static_cast<std::uint8_t>(40 + i % 97);
      std::vector<std::uint8_t> frame(background.begin(), background.begin() + width);
      for (std::uint8_t& value : frame)
        value = static_cast<std::uint8_t>(value + 20);
      std::vector<std::int32_t> left(blocks), top(blocks, 0), whole(blocks), offset(blocks);
      std::vector<std::int32_t> w00(blocks, kFixedOne), w01(blocks, 0), w10(blocks, 0),
          w11(blocks, 0);
      int partial = 0;
      for (int j = 0; j < blocks; ++j) {
        left[j] = j * kWarp;
        whole[j] = std::min(kWarp, width - j * kWarp) == kWarp && left[j] + kWarp <= width - 1;
        partial += 1 - whole[j];
        offset[j] = left[j];
      }
      std::vector<std::uint16_t> out(width, 7);
      const WarpRow warp{frame.data(),
                         frame.data(),
                         0,
                         0,
                         out.data(),
                         background.data(),
                         width,
                         left.data(),
                         top.data(),
                         whole.data(),
                         offset.data(),
                         w00.data(),
                         w01.data(),
                         w10.data(),
                         w11.data(),
                         blocks,
                         width,
                         width - 1,
                         height - 1,
                         partial};
      difference_row(warp);
      ASSERT_EQ(out, std::vector<std::uint16_t>(width, 20 * kFixedOne)) << "width " << width;
    }
  });
}

// Homographies near the identity (rolls, shifts, some perspective), and degenerate ones: a
// denominator through 0 (infinite and NaN positions), positions far outside.
TEST(Kernels, WarpBlocksMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(9);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    constexpr int kMost = 80;
    for (int trial = 0; trial < 200; ++trial) {
      WarpLine line{};
      const float v = 500.0f + 400.0f * unit(random);
      line.xnu = 1.0f + 0.01f * unit(random);
      line.xn0 = 30.0f * unit(random) + 0.005f * v * unit(random);
      line.ynu = 0.01f * unit(random);
      line.yn0 = v + 20.0f * unit(random);
      line.wnu = 1e-5f * unit(random);
      line.wn0 = 1.0f + 0.01f * unit(random);
      if (trial % 10 == 1) line.wn0 = -line.wnu * 1000.0f;  // through 0 at column 1000
      if (trial % 10 == 2) line.xn0 = 1e9f;                 // far outside
      if (trial % 10 == 3) line.yn0 = std::numeric_limits<float>::quiet_NaN();
      line.width = 2048 - trial % 40;
      line.stride = 2048 + 64;
      line.last_column = 2047;
      line.last_row = 1535 - trial % 3 * 500;
      line.far = 2.0f * 2048.0f;
      const int blocks = (line.width + WarpRow::kWarpBlock - 1) / WarpRow::kWarpBlock;
      const int first = trial % 7;
      std::vector<std::int32_t> got(8 * kMost, -9), expected(8 * kMost, -9);
      auto arrays = [&](std::vector<std::int32_t>& a) {
        std::int32_t* p = a.data();
        return WarpBlocks{p,
                          p + kMost,
                          p + 2 * kMost,
                          p + 3 * kMost,
                          p + 4 * kMost,
                          p + 5 * kMost,
                          p + 6 * kMost,
                          p + 7 * kMost};
      };
      const int partial = warp_blocks(line, first, blocks, arrays(got));
      const int partial_expected = reference::warp_blocks(line, first, blocks, arrays(expected));
      ASSERT_EQ(got, expected) << "trial " << trial;
      ASSERT_EQ(partial, partial_expected) << "trial " << trial;
    }
  });
}

template <class Sum, class Lane>
void check_band_pass(std::mt19937& random) {
  for (const int width : kWidths) {
    const int n = width + 1;
    const std::uint16_t most_row = sizeof(Sum) == 2 ? 255 << 4 : 255 << 7;
    auto inner = random_values<Sum>(random, n, 0, std::numeric_limits<Sum>::max());
    auto outer = random_values<Sum>(random, n, 0, std::numeric_limits<Sum>::max());
    const auto rows = random_values<std::uint16_t>(random, 4 * n, 0, most_row);
    auto inner_expected = inner, outer_expected = outer;
    std::vector<Lane> got(n, 5), expected(n, 5);
    for (const auto& [a, b] : {std::pair<Sum, Sum>{3, 1}, {19, 5}, {1, 1}}) {
      const int most =
          band_pass_row(inner.data(), rows.data(), rows.data() + n, outer.data(),
                        rows.data() + 2 * n, rows.data() + 3 * n, a, b, width, got.data());
      const int most_expected = reference::band_pass_row(
          inner_expected.data(), rows.data(), rows.data() + n, outer_expected.data(),
          rows.data() + 2 * n, rows.data() + 3 * n, a, b, width, expected.data());
      ASSERT_EQ(got, expected) << "width " << width;
      ASSERT_EQ(inner, inner_expected) << "width " << width;
      ASSERT_EQ(outer, outer_expected) << "width " << width;
      ASSERT_EQ(most, most_expected) << "width " << width;
    }
  }
}

TEST(Kernels, BandPassRowMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(3);
    check_band_pass<std::uint16_t, std::int16_t>(random);
    check_band_pass<std::uint32_t, std::int32_t>(random);
  });
}

template <class Lane>
void check_peak_bits(std::mt19937& random) {
  for (const int width : kWidths) {
    for (const int reach : {1, 2, 3, 5}) {
      // Few values: many ties, where "strictly above" and "at least" differ.
      const int rows = 2 * reach + 1;
      const auto ring = random_values<Lane>(random, static_cast<std::size_t>(rows) * (width + 1),
                                            std::numeric_limits<Lane>::min(),
                                            std::numeric_limits<Lane>::min() + 3);
      const auto small = random_values<Lane>(random, ring.size(), -3, 3);
      std::vector<std::size_t> slots(rows);
      for (int k = 0; k < rows; ++k)
        slots[k] = static_cast<std::size_t>((k * 5 + 2) % rows) * (width + 1);
      for (const Lane threshold : {std::numeric_limits<Lane>::min(), Lane{-1}, Lane{0}, Lane{2}}) {
        for (const auto* values : {&ring, &small}) {
          const std::size_t words = (width + 63) / 64;
          std::vector<std::uint64_t> got(words + 1, 0xdeadu), expected(words + 1, 0xdeadu);
          peak_bits(values->data(), slots.data() + reach, reach, threshold, width, got.data());
          reference::peak_bits(values->data(), slots.data() + reach, reach, threshold, width,
                               expected.data());
          ASSERT_EQ(got, expected) << "width " << width << " reach " << reach;
        }
      }
    }
  }
}

TEST(Kernels, PeakBitsMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(4);
    check_peak_bits<std::int16_t>(random);
    check_peak_bits<std::int32_t>(random);
  });
}

template <class Lane>
void check_window_sum(std::mt19937& random, Lane lo, Lane hi) {
  const int stride = 1040;
  for (const int rows : {0, 1, 9, 40}) {
    const auto ring =
        random_values<Lane>(random, static_cast<std::size_t>(2 * rows + 1) * stride + kWindowLanes,
                            lo, hi);  // (with the lanes the kernel may read past the last row)
    std::vector<std::size_t> offsets(static_cast<std::size_t>(2 * rows));  // a row left out
    for (int j = 0; j < 2 * rows; ++j)
      offsets[static_cast<std::size_t>(j)] =
          static_cast<std::size_t>(j < rows ? j : j + 1) * stride;
    for (const int width : kWidths) {
      for (const int first : {0, 3, 17}) {
        ASSERT_EQ(window_sum(ring.data(), offsets.data(), 2 * rows, first, width),
                  reference::window_sum(ring.data(), offsets.data(), 2 * rows, first, width))
            << "rows " << rows << " width " << width << " first " << first;
      }
    }
  }
}

// Many windows of a row at once, at columns in any order (repeated too), against the reference.
template <class Lane>
void check_window_sums(std::mt19937& random, Lane lo, Lane hi) {
  const int stride = 1040;
  for (const int rows : {0, 1, 10, 40}) {
    const auto ring = random_values<Lane>(
        random, static_cast<std::size_t>(2 * rows + 1) * stride + kWindowLanes, lo, hi);
    std::vector<std::size_t> offsets(static_cast<std::size_t>(2 * rows));  // a row left out
    for (int j = 0; j < 2 * rows; ++j)
      offsets[static_cast<std::size_t>(j)] =
          static_cast<std::size_t>(j < rows ? j : j + 1) * stride;
    for (const int width : kWidths) {
      if (width > stride) continue;
      std::uniform_int_distribution<std::int32_t> column(0, stride - width);
      for (const int n : {0, 1, 7, 100}) {
        std::vector<std::int32_t> firsts(static_cast<std::size_t>(n));
        for (std::int32_t& first : firsts)
          first = column(random);
        if (n > 1) firsts[1] = firsts[0];
        // (Half of them in order within a few vectors: windows near each other share columns.)
        std::uniform_int_distribution<std::int32_t> near(0, std::min(64, stride - width));
        for (int k = 2; k < n / 2; ++k)
          firsts[static_cast<std::size_t>(k)] = near(random);
        std::sort(firsts.begin(), firsts.begin() + n / 2);
        std::vector<std::uint64_t> sums(firsts.size() + 1, 7), expected(sums);
        window_sums(ring.data(), offsets.data(), 2 * rows, firsts.data(), n, width, sums.data());
        reference::window_sums(ring.data(), offsets.data(), 2 * rows, firsts.data(), n, width,
                               expected.data());
        ASSERT_EQ(sums, expected) << "rows " << rows << " width " << width << " windows " << n;
        for (int k = 0; k < n; ++k) {
          ASSERT_EQ(expected[static_cast<std::size_t>(k)],
                    reference::window_sum(ring.data(), offsets.data(), 2 * rows,
                                          firsts[static_cast<std::size_t>(k)], width));
        }
      }
    }
  }
}

TEST(Kernels, WindowSumsMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(6);
    check_window_sums<std::int16_t>(random, -32767, 32767);
    check_window_sums<std::int16_t>(random, -3, 3);
    check_window_sums<std::int32_t>(random, -2147483647, 2147483647);
  });
}

TEST(Kernels, WindowSumMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(5);
    // (The band-pass never reaches -2^15 either.)
    check_window_sum<std::int16_t>(random, -32767, 32767);
    check_window_sum<std::int16_t>(random, -3, 3);
    // (The band-pass never reaches -2^31.)
    check_window_sum<std::int32_t>(random, -2147483647, 2147483647);
  });
}

// Candidates against the candidates of a line before, on a coarse grid of positions and totals
// so that priors tie (the first of equals is chosen) and totals tie with the best so far (kept).
TEST(Kernels, BestPriorsMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(7);
    auto grid = [&](int steps, float step) { return step * static_cast<float>(random() % steps); };
    for (const int n : {0, 1, 3, 7, 8, 9, 16, 17, 40}) {
      for (const int m : {0, 1, 2, 8, 33}) {
        for (int trial = 0; trial < 20; ++trial) {
          const std::size_t padded =
              static_cast<std::size_t>((n + kSelectionLanes - 1) / kSelectionLanes) *
              kSelectionLanes;
          std::vector<float> position(padded), prior(static_cast<std::size_t>(m)),
              score(static_cast<std::size_t>(m)), best(padded);
          std::vector<std::int32_t> from(padded);
          for (std::size_t i = 0; i < padded; ++i) {
            position[i] = grid(40, 0.5f);
            best[i] = grid(30, 1.0f) - 10.0f;
            from[i] = static_cast<std::int32_t>(random() % 100) - 1;
          }
          for (std::size_t j = 0; j < prior.size(); ++j) {
            prior[j] = grid(40, 0.5f);
            score[j] = grid(20, 1.0f);
          }
          const PriorLine line{prior.data(),  score.data(),  m,       grid(4, 1.0f),
                               grid(3, 1.0f), grid(3, 1.0f), 1000 + m};
          std::vector<float> expected_best = best;
          std::vector<std::int32_t> expected_from = from;
          reference::best_priors(line, n, expected_best.data(), expected_from.data(),
                                 position.data());
          best_priors(line, n, best.data(), from.data(), position.data());
          for (int i = 0; i < n; ++i) {
            const auto at = static_cast<std::size_t>(i);
            ASSERT_EQ(best[at], expected_best[at]) << "n " << n << ", m " << m << ", i " << i;
            ASSERT_EQ(from[at], expected_from[at]) << "n " << n << ", m " << m << ", i " << i;
          }
        }
      }
    }
  });
}

// Columns with a Gaussian line, some clipped (at the image's ends too), on a textured frame
// minus a textured background seen along slanted lines through it.
TEST(Kernels, RefineColumnsMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(6);
    const int width = 120, height = 90, saturation = 250;
    std::vector<std::uint8_t> current = random_values<std::uint8_t>(random, width * height, 0, 60);
    const std::vector<std::uint8_t> background =
        random_values<std::uint8_t>(random, width * height, 0, 40);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const int n = 37;
    std::vector<std::int32_t> u(n), centre(n), lo(n), count(n), spacing(n), edge(n);
    std::vector<float> x0(n), y0(n), dx(n), dy(n);
    for (int j = 0; j < n; ++j) {
      u[j] = 2 + 3 * j;
      // Lines at any row, clipped ones among them (some reaching the first or last rows).
      const float row = j % 7 == 0 ? 1.0f : j % 11 == 0 ? height - 2.0f : 5 + unit(random) * 80;
      const float sigma = 0.6f + 2.0f * unit(random);
      const float peak = j % 3 == 0 ? 400.0f : 60 + 150 * unit(random);
      for (int v = 0; v < height; ++v) {
        const float d = (static_cast<float>(v) - row) / sigma;
        const float value = current[v * width + u[j]] + peak * std::exp(-0.5f * d * d);
        current[v * width + u[j]] = static_cast<std::uint8_t>(std::min(value, 255.0f));
      }
      centre[j] = std::clamp(static_cast<int>(row + 0.5f), 0, height - 1);
      const int reach = 1 + j % 6;
      lo[j] = std::max(centre[j] - reach, 0);
      count[j] = std::min(centre[j] + reach, height - 1) - lo[j] + 1;
      spacing[j] = 1 + j % 3;
      edge[j] = 3 + j % 5;
      // Through the background: inside it for rows [0, height) and 4 columns from its right.
      x0[j] = 10 + 90 * unit(random);
      dx[j] = (unit(random) - 0.5f) * 0.05f;
      dy[j] = 0.95f + 0.02f * unit(random);
      y0[j] = static_cast<float>(centre[j]) * dy[j] + 0.4f * unit(random);
      y0[j] = std::min(y0[j], static_cast<float>(centre[j]));
    }
    RefineColumns columns{u.data(),          centre.data(), lo.data(),      count.data(),
                          spacing.data(),    edge.data(),   x0.data(),      y0.data(),
                          dx.data(),         dy.data(),     current.data(), width,
                          background.data(), width,         height - 1,     saturation};
    for (const int m : {0, 1, 3, 7, 8, 9, 16, 17, n}) {
      std::vector<float> got(n + 1, -5.0f), expected(n + 1, -5.0f);
      refine_columns(columns, m, got.data());
      reference::refine_columns(columns, m, expected.data());
      ASSERT_EQ(std::memcmp(got.data(), expected.data(), got.size() * sizeof(float)), 0)
          << "columns " << m;
    }
  });
}

// Columns [begin, end) of images with plateaus of their largest value (first and last row
// differ), columns of zeros, of 255 and random ones; heights past a flush of the 16-bit sums.
TEST(Kernels, ColumnMaximaMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(7);
    for (const int height : {1, 2, 255, 256, 257, 700}) {
      for (const int width : {1, 15, 16, 33, 100, 301}) {
        const int stride = width + 5;
        auto image =
            random_values<std::uint8_t>(random, static_cast<std::size_t>(stride) * height, 0, 255);
        for (int v = 0; v < height; ++v) {
          for (int u = 0; u < width; u += 7)
            image[v * stride + u] = u % 2 == 0 ? 0 : 255;
          if (v % 3 == 0 && width > 3) image[v * stride + 3] = 200;  // a plateau in column 3
        }
        for (const auto& [begin, end] : {std::pair{0, width}, std::pair{width / 3, width}}) {
          std::vector<std::uint8_t> max(width, 9), max_expected(width, 9);
          std::vector<std::uint16_t> first(width, 9), first_expected(width, 9);
          std::vector<std::uint16_t> last(width, 9), last_expected(width, 9);
          std::vector<std::uint32_t> sum(width, 9), sum_expected(width, 9);
          column_maxima(image.data(), stride, begin, end, height, max.data(), first.data(),
                        last.data(), sum.data());
          reference::column_maxima(image.data(), stride, begin, end, height, max_expected.data(),
                                   first_expected.data(), last_expected.data(),
                                   sum_expected.data());
          ASSERT_EQ(max, max_expected) << height << " x " << width << " from " << begin;
          ASSERT_EQ(first, first_expected) << height << " x " << width << " from " << begin;
          ASSERT_EQ(last, last_expected) << height << " x " << width << " from " << begin;
          ASSERT_EQ(sum, sum_expected) << height << " x " << width << " from " << begin;
        }
      }
    }
  });
}

TEST(Kernels, DownsampleRowMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(8);
    for (const int width : kWidths) {
      const auto a =
          random_values<std::uint8_t>(random, 2 * static_cast<std::size_t>(width), 0, 255);
      const auto b =
          random_values<std::uint8_t>(random, 2 * static_cast<std::size_t>(width), 0, 255);
      std::vector<std::uint8_t> out(static_cast<std::size_t>(width) + 1, 7), expected = out;
      reference::downsample_row(a.data(), b.data(), width, expected.data());
      downsample_row(a.data(), b.data(), width, out.data());
      ASSERT_EQ(out, expected) << "width " << width;
    }
    // Four pixels at 255 and at 0, and sums just under and at a multiple of 4 (rounding).
    const std::vector<std::uint8_t> high(64, 255), low(64, 0), odd(64, 1);
    std::vector<std::uint8_t> out(32);
    downsample_row(high.data(), high.data(), 32, out.data());
    EXPECT_EQ(out[0], 255);
    downsample_row(low.data(), odd.data(), 32, out.data());
    EXPECT_EQ(out[31], 1);  // (2 + 2) / 4
    downsample_row(low.data(), low.data(), 32, out.data());
    EXPECT_EQ(out[5], 0);
  });
}

TEST(Kernels, CopyRowsPastCacheMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(8);
    constexpr int kRows = 3;
    for (const int width : kWidths) {
      // Destinations at every offset from a 128-byte boundary, so that rows start aligned and
      // unaligned to every vector size; the bytes between and after the rows are left alone.
      for (const int offset : {0, 1, 7, 31, 63, 64, 65, 127}) {
        const std::ptrdiff_t src_stride = width + 5, dst_stride = width + 3;
        const auto source = random_values<std::uint8_t>(
            random, static_cast<std::size_t>(src_stride * kRows), 0, 255);
        std::vector<std::uint8_t> got(static_cast<std::size_t>(dst_stride * kRows + 256), 9);
        std::vector<std::uint8_t> expected = got;
        const std::size_t skip =
            (128 - reinterpret_cast<std::uintptr_t>(got.data()) % 128) % 128 + offset;
        copy_rows_past_cache(source.data(), src_stride, got.data() + skip, dst_stride, width,
                             kRows);
        reference::copy_rows_past_cache(source.data(), src_stride, expected.data() + skip,
                                        dst_stride, width, kRows);
        ASSERT_EQ(got, expected) << "width " << width << " at offset " << offset;
      }
    }
  });
}

TEST(Kernels, SlideStructureRowMatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(8);
    for (const int width : kWidths) {
      const auto size = static_cast<std::size_t>(width) + 2;
      // Three rows of pixels (the extremes side by side: the largest differences), the products
      // of the row three above and the running sums.
      const auto up = random_values<std::uint8_t>(random, size, 0, 255);
      const auto mid = random_values<std::uint8_t>(random, size, 0, 255);
      const auto down = random_values<std::uint8_t>(random, size, 0, 255);
      std::vector<std::vector<std::int32_t>> got;
      for (int k = 0; k < 6; ++k)
        got.push_back(random_values<std::int32_t>(random, size, -65025, 65025));
      auto expected = got;
      slide_structure_row(up.data(), mid.data(), down.data(), got[0].data(), got[1].data(),
                          got[2].data(), got[3].data(), got[4].data(), got[5].data(), 1, width + 1);
      reference::slide_structure_row(up.data(), mid.data(), down.data(), expected[0].data(),
                                     expected[1].data(), expected[2].data(), expected[3].data(),
                                     expected[4].data(), expected[5].data(), 1, width + 1);
      ASSERT_EQ(got, expected) << "width " << width;
    }
    // One pixel: gx = 255 - 0, gy = 0 - 255, replacing products of 1 in sums of 10.
    const std::vector<std::uint8_t> up{0, 255, 0}, mid{0, 7, 255}, down{0, 0, 0};
    std::vector<std::int32_t> xx(3, 1), xy(3, 1), yy(3, 1), sxx(3, 10), sxy(3, 10), syy(3, 10);
    slide_structure_row(up.data(), mid.data(), down.data(), xx.data(), xy.data(), yy.data(),
                        sxx.data(), sxy.data(), syy.data(), 1, 2);
    EXPECT_EQ(xx[1], 65025);
    EXPECT_EQ(xy[1], -65025);
    EXPECT_EQ(yy[1], 65025);
    EXPECT_EQ(sxx[1], 65034);
    EXPECT_EQ(sxy[1], -65016);
    EXPECT_EQ(syy[1], 65034);
  });
}

TEST(Kernels, CornerScoresMatchTheReference) {
  for_each_target([] {
    std::mt19937 random(8);
    // Column sums of three rows of doubled central differences: |products| up to 3 * 255^2.
    constexpr std::int32_t kMost = 3 * 255 * 255;
    for (const int width : kWidths) {
      const auto size = static_cast<std::size_t>(width) + 2;
      const auto xx = random_values<std::int32_t>(random, size, 0, kMost);
      const auto yy = random_values<std::int32_t>(random, size, 0, kMost);
      const auto xy = random_values<std::int32_t>(random, size, -kMost, kMost);
      std::vector<float> got(size, -1.0f), expected = got;
      corner_scores(xx.data(), xy.data(), yy.data(), 1, width + 1, got.data());
      reference::corner_scores(xx.data(), xy.data(), yy.data(), 1, width + 1, expected.data());
      for (std::size_t u = 0; u < size; ++u) {
        ASSERT_EQ(std::bit_cast<std::uint32_t>(got[u]), std::bit_cast<std::uint32_t>(expected[u]))
            << "width " << width << " at " << u;
      }
    }
    // A flat window, an edge (one eigenvalue 0) and an isotropic corner.
    const std::vector<std::int32_t> zero(3, 0), one(3, 1), hundred(3, 100);
    std::array<float, 3> scores{};
    const float& score = scores[1];
    corner_scores(zero.data(), zero.data(), zero.data(), 1, 2, scores.data());
    EXPECT_EQ(score, 0.0f);
    corner_scores(hundred.data(), zero.data(), zero.data(), 1, 2, scores.data());
    EXPECT_EQ(score, 0.0f);
    corner_scores(hundred.data(), zero.data(), hundred.data(), 1, 2, scores.data());
    EXPECT_EQ(score, 300.0f);
    corner_scores(one.data(), one.data(), one.data(), 1, 2, scores.data());
    EXPECT_EQ(score, 0.0f);
  });
}

TEST(Kernels, Transpose16MatchesTheReference) {
  for_each_target([] {
    std::mt19937 random(8);
    const auto source = random_values<std::uint8_t>(random, 16 * 21, 0, 255);
    std::vector<std::uint8_t> got(16 * 19, 3), expected(16 * 19, 3);
    transpose16(source.data(), 21, got.data(), 19);
    reference::transpose16(source.data(), 21, expected.data(), 19);
    ASSERT_EQ(got, expected);
  });
}

}  // namespace
}  // namespace laserline::pipeline::kernels
