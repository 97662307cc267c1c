// The pixel conversion kernels (camera buffer -> the laser's mono8) against the per-pixel
// reference of pixel_reference.hpp: every layout, every Bayer phase, 8 and 16-bit samples, frame
// edges, odd sizes, padded rows, negative weights and clipping; and a few values by hand.
#include "hal/pixel_conversion.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "pixel_reference.hpp"
#include "thread_allocations.hpp"

namespace laserline::hal {
namespace {

struct Case {
  const char* name;
  SourceFormat format;
};

std::vector<Case> all_formats() {
  std::vector<Case> cases = {
      {"Mono8", {PixelLayout::kMono, 8}},
      {"Mono12", {PixelLayout::kMono, 12}},
      {"Mono16", {PixelLayout::kMono, 16}},
      {"RGB8", {PixelLayout::kRgb, 8}},
      {"BGR8", {PixelLayout::kBgr, 8}},
      {"YUYV 601 limited", {PixelLayout::kYuyv, 8, YuvMatrix::kBt601, YuvRange::kLimited}},
      {"YUYV 601 full", {PixelLayout::kYuyv, 8, YuvMatrix::kBt601, YuvRange::kFull}},
      {"YUYV 709 limited", {PixelLayout::kYuyv, 8, YuvMatrix::kBt709, YuvRange::kLimited}},
      {"YUYV 709 full", {PixelLayout::kYuyv, 8, YuvMatrix::kBt709, YuvRange::kFull}},
  };
  const std::pair<const char*, PixelLayout> mosaics[] = {{"RGGB", PixelLayout::kBayerRggb},
                                                         {"GRBG", PixelLayout::kBayerGrbg},
                                                         {"GBRG", PixelLayout::kBayerGbrg},
                                                         {"BGGR", PixelLayout::kBayerBggr}};
  static std::vector<std::string> names;  // the cases point into it
  names.reserve(16);
  for (const auto& [mosaic, layout] : mosaics) {
    for (int bits : {8, 12, 16}) {
      names.push_back(std::string("Bayer ") + mosaic + " " + std::to_string(bits) + "-bit");
      cases.push_back({names.back().c_str(), {layout, bits}});
    }
  }
  return cases;
}

const char* const kChannels[] = {"red",
                                 "green",
                                 "blue",
                                 "grey",
                                 "red - (green + blue) / 2",
                                 "2*green - red - blue",
                                 "1.5*blue - 0.25*red",
                                 "0.3*red + 0.3*green + 0.3*blue",
                                 "red + green"};

// A frame of random samples with padded rows (the padding filled too, so that reading it shows),
// a fifth of them at the extremes so that sums clip both ways. 12-bit samples sometimes carry
// bits above their 12, which must clip, not wrap.
std::vector<std::uint8_t> random_frame(const SourceFormat& format, int height, std::size_t stride,
                                       std::mt19937& rng) {
  std::vector<std::uint8_t> frame(stride * static_cast<std::size_t>(height));
  std::uniform_int_distribution<int> byte(0, 255);
  std::uniform_int_distribution<int> pick(0, 9);
  const int max = format.bits > 8 ? (1 << format.bits) - 1 : 255;
  std::uniform_int_distribution<int> value(0, max);
  if (format.bits <= 8) {
    for (auto& b : frame) {
      const int p = pick(rng);
      b = static_cast<std::uint8_t>(p == 0 ? 0 : p == 1 ? 255 : byte(rng));
    }
    return frame;
  }
  for (std::size_t i = 0; i + 1 < frame.size(); i += 2) {
    const int p = pick(rng);
    const int v = p == 0 ? 0 : p == 1 ? max : p == 2 ? 65535 : value(rng);
    frame[i] = static_cast<std::uint8_t>(v & 0xff);
    frame[i + 1] = static_cast<std::uint8_t>(v >> 8);
  }
  return frame;
}

TEST(PixelConversion, EveryLayoutChannelAndSizeMatchesTheReference) {
  const std::pair<int, int> sizes[] = {{2, 2}, {3, 2},  {2, 3},   {3, 3},   {4, 4},  {5, 7},
                                       {8, 3}, {66, 9}, {67, 10}, {131, 5}, {40, 40}};
  std::mt19937 rng(7);
  int checked = 0;
  for (const Case& c : all_formats()) {
    for (const char* channel_text : kChannels) {
      const LaserChannel channel = parse_laser_channel(channel_text);
      for (const auto& [width, height] : sizes) {
        if (!conversion_problem(c.format, width, height).empty()) continue;
        const PixelConverter converter(c.format, width, height, channel);
        // Rows padded by a few bytes (an even number: 16-bit samples stay aligned).
        const std::size_t stride = converter.row_bytes() + 6;
        const auto frame = random_frame(c.format, height, stride, rng);
        // Output rows padded too, with a sentinel that must survive.
        const std::size_t out_stride = static_cast<std::size_t>(width) + 3;
        std::vector<std::uint8_t> out(out_stride * static_cast<std::size_t>(height), 0xA5);
        converter.convert(frame.data(), stride, out.data(), out_stride);
        std::vector<std::uint8_t> packed;
        for (int y = 0; y < height; ++y) {
          const auto* row = out.data() + static_cast<std::size_t>(y) * out_stride;
          packed.insert(packed.end(), row, row + width);
          for (std::size_t x = static_cast<std::size_t>(width); x < out_stride; ++x)
            ASSERT_EQ(row[x], 0xA5) << c.name << ": wrote past the row's width";
        }
        const auto reference =
            test::reference_values(frame.data(), stride, width, height, c.format, channel);
        ASSERT_EQ(test::compare_with_reference(packed, reference, width, channel), "")
            << c.name << ", channel " << channel_text << ", " << width << "x" << height;
        ++checked;
      }
    }
  }
  // 21 formats by 11 sizes, less the 5 odd widths of the 4 YUYV formats, by 9 channels.
  EXPECT_EQ(checked, (21 * 11 - 4 * 5) * 9);
}

// The definition on a small mosaic, computed by hand: red on RGGB keeps the red sites and fills
// the others from the nearest red sites only.
TEST(PixelConversion, BayerSingleColourByHand) {
  // RGGB, 4x3. Red sites (even x, even y) 10, 30 / 50, 70; every other site 200.
  const std::vector<std::uint8_t> mosaic = {
      10,  200, 30,  200,  //
      200, 200, 200, 200,  //
      50,  200, 70,  200,  //
  };
  const PixelConverter red({PixelLayout::kBayerRggb, 8}, 4, 3, parse_laser_channel("red"));
  std::vector<std::uint8_t> out(12);
  red.convert(mosaic.data(), 4, out.data(), 4);
  const std::vector<std::uint8_t> expected = {
      10, 20, 30, 30,  // (10+30)/2; at the right edge only the red site on its left
      30, 40, 50, 50,  // (10+50)/2, (10+30+50+70)/4, (30+70)/2, (30+70)/2
      50, 60, 70, 70,
  };
  EXPECT_EQ(out, expected);

  // Green on the same mosaic: the green sites are 200, so every pixel is 200 (a red or blue site
  // takes the mean of its four, or at an edge three or two, green neighbours).
  const PixelConverter green({PixelLayout::kBayerRggb, 8}, 4, 3, parse_laser_channel("green"));
  green.convert(mosaic.data(), 4, out.data(), 4);
  EXPECT_EQ(out, std::vector<std::uint8_t>(12, 200));
}

// Why a weighted difference: white light is equally bright in red, green and blue and cancels;
// a red laser does not.
TEST(PixelConversion, WeightedDifferenceCancelsWhiteLightOnAMosaic) {
  constexpr int kWidth = 16, kHeight = 12;
  // GRBG, a white wall at 120 with a red laser line on row 6 (red sites +100).
  std::vector<std::uint8_t> mosaic(kWidth * kHeight, 120);
  for (int x = 1; x < kWidth; x += 2)
    mosaic[6 * kWidth + x] = 220;  // red sites of row 6 (GRBG: odd x of even rows)
  const PixelConverter converter({PixelLayout::kBayerGrbg, 8}, kWidth, kHeight,
                                 parse_laser_channel("red - (green + blue) / 2"));
  std::vector<std::uint8_t> out(kWidth * kHeight);
  converter.convert(mosaic.data(), kWidth, out.data(), kWidth);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const int v = out[static_cast<std::size_t>(y * kWidth + x)];
      if (y == 6) {
        EXPECT_EQ(v, 100) << x;  // the line's own row: red 220 (own or both neighbours)
      } else if (y == 5 || y == 7) {
        EXPECT_EQ(v, 50) << x << ", " << y;  // half of the red neighbours are on the line
      } else {
        EXPECT_EQ(v, 0) << x << ", " << y;
      }
    }
  }
}

TEST(PixelConversion, Mono16KeepsTheTopBitsAndClips) {
  // Mono16: v >> 8. Mono12: v >> 4, and values past 12 bits clip at 255.
  const std::vector<std::uint8_t> words = {0xff, 0x12, 0x00, 0x01, 0xff, 0xff, 0x34, 0x0a};
  std::vector<std::uint8_t> out(4);
  PixelConverter({PixelLayout::kMono, 16}, 4, 1, LaserChannel{})
      .convert(words.data(), 8, out.data(), 4);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{0x12, 0x01, 0xff, 0x0a}));
  PixelConverter({PixelLayout::kMono, 12}, 4, 1, LaserChannel{})
      .convert(words.data(), 8, out.data(), 4);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{255, 0x10, 255, 0xa3}));
}

TEST(PixelConversion, FramesItCannotTakeAreOneLineProblems) {
  EXPECT_EQ(conversion_problem({PixelLayout::kBayerRggb, 8}, 1, 480),
            "a Bayer mosaic needs at least 2x2 pixels, got 1x480");
  EXPECT_EQ(conversion_problem({PixelLayout::kBayerGbrg, 16}, 640, 1),
            "a Bayer mosaic needs at least 2x2 pixels, got 640x1");
  EXPECT_EQ(conversion_problem({PixelLayout::kYuyv, 8}, 641, 480),
            "YUYV needs an even width (pixels come in pairs), got 641x480");
  EXPECT_EQ(conversion_problem({PixelLayout::kRgb, 16}, 640, 480),
            "16-bit samples are not supported in this layout");
  EXPECT_EQ(conversion_problem({PixelLayout::kMono, 8}, 0, 480), "no pixels in a 0x480 frame");
  EXPECT_EQ(conversion_problem({PixelLayout::kMono, 8}, 1, 1), "");
  EXPECT_THROW(PixelConverter({PixelLayout::kBayerRggb, 8}, 1, 1, LaserChannel{}),
               std::invalid_argument);
}

TEST(PixelConversion, ConvertingAllocatesNothing) {
  const PixelConverter converter({PixelLayout::kBayerBggr, 8}, 640, 480,
                                 parse_laser_channel("red - (green + blue) / 2"));
  std::vector<std::uint8_t> in(640 * 480, 77), out(640 * 480);
  {
    test::ThreadAllocationCount probe_count;
    void* volatile probe = std::malloc(64);
    std::free(probe);
    ASSERT_EQ(probe_count.count(), 1) << "the allocation counter does not count";
  }
  test::ThreadAllocationCount allocations;
  converter.convert(in.data(), 640, out.data(), 640);
  EXPECT_EQ(allocations.count(), 0);
}

}  // namespace
}  // namespace laserline::hal
