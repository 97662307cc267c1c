// The pixel conversion kernels (camera buffer -> the laser's mono8) against the per-pixel
// reference of pixel_reference.hpp: every layout, every Bayer phase, 8 and 16-bit samples, frame
// edges, odd sizes, padded rows, negative weights and clipping; and a few values by hand.
#include "hal/pixel_conversion.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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
  int changed_by_clipping = 0;  // pixels the clipping rule set to 255 where the sum was below
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
        for (const auto& r : reference)
          changed_by_clipping += r.clipped && r.weighted < 254.5 ? 1 : 0;
      }
    }
  }
  // 21 formats by 11 sizes, less the 5 odd widths of the 4 YUYV formats, by 9 channels.
  EXPECT_EQ(checked, (21 * 11 - 4 * 5) * 9);
  EXPECT_GT(changed_by_clipping, 1000) << "the frames hardly test the clipping rule";
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

// The clipping rule by hand: a positively weighted colour at the top of the sample range gives
// 255, whatever the others say; one step below it, or a negatively weighted colour, does not.
TEST(PixelConversion, ClippedColourGives255ByHand) {
  const LaserChannel red_laser = parse_laser_channel("red - (green + blue) / 2");
  std::vector<std::uint8_t> out(4);
  // RGB8 and BGR8: red 255 gives 255 (the sum is 255 - 200 = 55), red 254 gives 54.
  const std::vector<std::uint8_t> rgb = {255, 200, 200, 254, 200, 200, 255, 255, 255, 0, 0, 0};
  PixelConverter({PixelLayout::kRgb, 8}, 4, 1, red_laser).convert(rgb.data(), 12, out.data(), 4);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{255, 54, 255, 0}));
  const std::vector<std::uint8_t> bgr = {200, 200, 255, 200, 200, 254, 255, 255, 255, 0, 0, 0};
  PixelConverter({PixelLayout::kBgr, 8}, 4, 1, red_laser).convert(bgr.data(), 12, out.data(), 4);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{255, 54, 255, 0}));
  // A negatively weighted colour clipped changes nothing: green - red of (255, 100, 0) is 0.
  const PixelConverter green_laser({PixelLayout::kRgb, 8}, 4, 1,
                                   parse_laser_channel("green - red"));
  green_laser.convert(rgb.data(), 12, out.data(), 4);  // green 200, 200, 255, 0
  EXPECT_EQ(out, (std::vector<std::uint8_t>{0, 0, 255, 0}));
  // Grey weighs every colour positively: a clipped blue alone gives 255.
  const std::vector<std::uint8_t> blue = {0, 0, 255, 0, 0, 254, 10, 10, 10, 0, 0, 0};
  PixelConverter({PixelLayout::kRgb, 8}, 4, 1, parse_laser_channel("grey"))
      .convert(blue.data(), 12, out.data(), 4);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{255, 29, 10, 0}));

  // RGGB, 4x3: red sites 255, 255 / 255, 100; green and blue sites 60. A pixel is clipped in red
  // when all its red neighbours are 255: the blue site at (1, 1) has three of four, so it is
  // (255 * 3 + 100) / 4 - (60 + 60) / 2 = 156.25.
  const std::vector<std::uint8_t> mosaic = {
      255, 60, 255, 60,  //
      60,  60, 60,  60,  //
      255, 60, 100, 60,  //
  };
  std::vector<std::uint8_t> frame(12);
  PixelConverter({PixelLayout::kBayerRggb, 8}, 4, 3, red_laser)
      .convert(mosaic.data(), 4, frame.data(), 4);
  const std::vector<std::uint8_t> expected = {
      255, 255, 255, 255,  // red 255 at each pixel (the right edge: its one red neighbour)
      255, 156, 118, 118,  // (0, 1): red above and below 255; the others see the 100
      255, 118, 40,  40,   // (255 + 100) / 2 - 60 = 117.5; 100 - 60
  };
  EXPECT_EQ(frame, expected);

  // 12 bit: the top code is 4095; 4094 is a value like any other (4094 / 16 - 60 = 195.875).
  for (const int top_red : {4095, 4094}) {
    std::vector<std::uint8_t> words;
    for (const int v : {top_red, 960, 960, 960}) {  // RGGB 2x2, green and blue 60 in 8-bit units
      words.push_back(static_cast<std::uint8_t>(v & 0xff));
      words.push_back(static_cast<std::uint8_t>(v >> 8));
    }
    PixelConverter({PixelLayout::kBayerRggb, 12}, 2, 2, red_laser)
        .convert(words.data(), 4, out.data(), 2);
    const int clipped = top_red == 4095 ? 255 : 196;
    EXPECT_EQ(out, (std::vector<std::uint8_t>{
                       static_cast<std::uint8_t>(clipped), static_cast<std::uint8_t>(clipped),
                       static_cast<std::uint8_t>(clipped), static_cast<std::uint8_t>(clipped)}))
        << top_red;
  }
}

// A red laser line that clips the camera's red channel, across bright and dark white-lit
// texture, through red - (green + blue) / 2: its core must be a run of 255 in every column (what
// the detectors centre from its flanks), the same rows along the whole line on every mosaic
// phase (no 255 on every other pixel), and every pixel off the clipped run the weighted sum as
// before. Without the rule the core is 255 - (G + B) / 2, a flat top that follows the texture.
TEST(PixelConversion, ClippedLaserLineIsARunOf255AcrossTexture) {
  constexpr int kWidth = 64, kHeight = 33, kBlock = 8;  // texture: blocks of 8 columns
  const LaserChannel channel = parse_laser_channel("red - (green + blue) / 2");
  std::vector<Case> cases = {{"RGB8", {PixelLayout::kRgb, 8}}, {"BGR8", {PixelLayout::kBgr, 8}}};
  for (const Case& c : all_formats()) {
    if (c.format.layout != PixelLayout::kMono && c.format.layout != PixelLayout::kRgb &&
        c.format.layout != PixelLayout::kBgr && c.format.layout != PixelLayout::kYuyv &&
        c.format.bits != 16) {
      cases.push_back(c);  // every Bayer phase, 8 and 12 bit
    }
  }
  ASSERT_EQ(cases.size(), 10u);
  for (const int centre : {16, 17}) {  // the line's centre row on both row parities
    for (const Case& c : cases) {
      SCOPED_TRACE(std::string(c.name) + ", line at row " + std::to_string(centre));
      const int unit = 1 << (c.format.bits - 8), top = c.format.bits > 8 ? unit * 256 - 1 : 255;
      // The scene in 8-bit units: white light of texture t (bright 180 + a little, dark 30 + a
      // little) on every colour, and the laser's red, 400 at its centre (a Gaussian of sigma 2
      // rows): red clips, within a row of the centre whatever the texture.
      auto texture = [&](int x, int y) {
        return ((x / kBlock) % 2 == 0 ? 180 : 30) + (x * 7 + y * 13) % 11;
      };
      auto colour = [&](int x, int y, int k) {  // k: 0 red, 1 green, 2 blue; in sample units
        const double d = y - centre;
        const double laser = k == 0 ? 400.0 * std::exp(-d * d / 8.0) : 0.0;
        return std::min(top, static_cast<int>(unit * (texture(x, y) + laser)));
      };
      const PixelConverter converter(c.format, kWidth, kHeight, channel);
      const std::size_t stride = converter.row_bytes();
      std::vector<std::uint8_t> buffer(stride * kHeight);
      const char* mosaic = test::reference_mosaic(c.format.layout);
      for (int y = 0; y < kHeight; ++y) {
        for (int x = 0; x < kWidth; ++x) {
          std::uint8_t* row = buffer.data() + static_cast<std::size_t>(y) * stride;
          if (mosaic == nullptr) {  // RGB or BGR
            const bool bgr = c.format.layout == PixelLayout::kBgr;
            for (int k = 0; k < 3; ++k)
              row[3 * x + (bgr ? 2 - k : k)] = static_cast<std::uint8_t>(colour(x, y, k));
          } else {
            const char site = mosaic[2 * (y % 2) + x % 2];
            const int v = colour(x, y, site == 'R' ? 0 : site == 'G' ? 1 : 2);
            if (c.format.bits == 8) {
              row[x] = static_cast<std::uint8_t>(v);
            } else {
              row[2 * x] = static_cast<std::uint8_t>(v & 0xff);
              row[2 * x + 1] = static_cast<std::uint8_t>(v >> 8);
            }
          }
        }
      }
      std::vector<std::uint8_t> out(static_cast<std::size_t>(kWidth) * kHeight);
      converter.convert(buffer.data(), stride, out.data(), kWidth);
      const auto reference =
          test::reference_values(buffer.data(), stride, kWidth, kHeight, c.format, channel);
      ASSERT_EQ(test::compare_with_reference(out, reference, kWidth, channel), "");
      auto at = [&](int x, int y) { return out[static_cast<std::size_t>(y * kWidth + x)]; };
      for (int x = 0; x < kWidth; ++x) {
        // The core: 255 on the three rows about the centre, in every column.
        for (int y = centre - 1; y <= centre + 1; ++y)
          ASSERT_EQ(at(x, y), 255) << x << ", " << y;
        // One run of 255 in each column; off it no clipped colour, so (compared above) the
        // weighted sum as before, and below 255.
        int first = centre, last = centre;
        while (first > 0 && at(x, first - 1) == 255)
          --first;
        while (last < kHeight - 1 && at(x, last + 1) == 255)
          ++last;
        for (int y = 0; y < kHeight; ++y) {
          if (y >= first && y <= last) continue;
          const auto& r = reference[static_cast<std::size_t>(y * kWidth + x)];
          ASSERT_FALSE(r.clipped) << x << ", " << y;
          ASSERT_LT(r.weighted, 254.5) << x << ", " << y;
        }
      }
      // Along the line, inside each block of texture (away from its edges, where neighbours
      // mix two textures): a row is 255 in every column or in none, on every mosaic phase.
      for (int y = 0; y < kHeight; ++y) {
        for (int block = 0; block < kWidth / kBlock; ++block) {
          const int x0 = block * kBlock + 1, x1 = block * kBlock + kBlock - 2;
          for (int x = x0 + 1; x <= x1; ++x) {
            ASSERT_EQ(at(x, y) == 255, at(x0, y) == 255) << x << ", " << y;
          }
        }
      }
      // The rule is what makes the core 255: on bright texture the weighted sum there is low.
      const auto& bright_core = reference[static_cast<std::size_t>(centre * kWidth + 3)];
      EXPECT_TRUE(bright_core.clipped);
      EXPECT_LT(bright_core.weighted, 100.0);
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
