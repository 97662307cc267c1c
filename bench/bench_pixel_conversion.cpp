// The camera-side pixel conversion (hal/pixel_conversion.hpp) at 2048x1536, single thread, beside
// a straightforward stock-OpenCV composition in the same run:
//   pixel_conversion/<case>:           our kernel, camera buffer -> the laser's mono8
//   pixel_reference_opencv/<case>:     cvtColor to BGR (bilinear demosaic for Bayer, YUYV to BGR),
//                                      then extractChannel (one colour) or transform (a weighted
//                                      sum) to 8 bits
// Counter `differ` is the fraction of pixels whose values differ between the two (OpenCV's
// demosaic treats the frame's edges and rounds its YUV matrix its own way, and ours gives 255
// where a positively weighted colour is clipped; inside, a single colour on a mosaic is the same
// bilinear interpolation).
// Run: build/default/bench/laserline_bench --benchmark_filter=pixel_
#include <benchmark/benchmark.h>

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "hal/laser_channel.hpp"
#include "hal/pixel_conversion.hpp"

namespace {

using namespace laserline;

constexpr int kWidth = 2048, kHeight = 1536;

struct ConversionCase {
  const char* name;
  hal::SourceFormat format;
  const char* channel;
  int opencv_code;  // to BGR; -1: the buffer is BGR already
};

const ConversionCase kCases[] = {
    {"BayerRG8/green", {hal::PixelLayout::kBayerRggb, 8}, "green", cv::COLOR_BayerBG2BGR},
    {"BayerRG8/red", {hal::PixelLayout::kBayerRggb, 8}, "red", cv::COLOR_BayerBG2BGR},
    {"BayerRG8/red-(green+blue)/2",
     {hal::PixelLayout::kBayerRggb, 8},
     "red - (green + blue) / 2",
     cv::COLOR_BayerBG2BGR},
    {"BayerRG8/grey", {hal::PixelLayout::kBayerRggb, 8}, "grey", cv::COLOR_BayerBG2BGR},
    {"BayerRG16/red-(green+blue)/2",
     {hal::PixelLayout::kBayerRggb, 16},
     "red - (green + blue) / 2",
     cv::COLOR_BayerBG2BGR},
    {"BGR8/red", {hal::PixelLayout::kBgr, 8}, "red", -1},
    {"BGR8/red-(green+blue)/2", {hal::PixelLayout::kBgr, 8}, "red - (green + blue) / 2", -1},
    {"YUYV/red-(green+blue)/2",
     {hal::PixelLayout::kYuyv, 8, hal::YuvMatrix::kBt601, hal::YuvRange::kLimited},
     "red - (green + blue) / 2",
     cv::COLOR_YUV2BGR_YUYV},
};

// A camera buffer of random content (the kernels do not branch on it).
std::vector<std::uint8_t> camera_buffer(const hal::SourceFormat& format) {
  std::vector<std::uint8_t> buffer(static_cast<std::size_t>(kWidth) * kHeight *
                                   static_cast<std::size_t>(format.bytes_per_pixel()));
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> byte(0, 255);
  for (auto& b : buffer)
    b = static_cast<std::uint8_t>(byte(rng));
  return buffer;
}

cv::Mat wrap(const ConversionCase& c, std::vector<std::uint8_t>& buffer) {
  switch (c.format.layout) {
    case hal::PixelLayout::kBgr:
      return cv::Mat(kHeight, kWidth, CV_8UC3, buffer.data());
    case hal::PixelLayout::kYuyv:
      return cv::Mat(kHeight, kWidth, CV_8UC2, buffer.data());
    default:
      return cv::Mat(kHeight, kWidth, c.format.bits > 8 ? CV_16UC1 : CV_8UC1, buffer.data());
  }
}

// The stock composition: a full BGR image, then one channel or a weighted sum.
void opencv_reference(const ConversionCase& c, const hal::LaserChannel& channel, const cv::Mat& in,
                      cv::Mat& bgr, cv::Mat& out) {
  const cv::Mat* colour = &in;
  if (c.opencv_code >= 0) {
    cv::cvtColor(in, bgr, c.opencv_code);
    colour = &bgr;
  }
  const double scale = c.format.bits > 8 ? 1.0 / (1 << (c.format.bits - 8)) : 1.0;
  if (channel.single() && scale == 1.0) {
    cv::extractChannel(*colour, out, channel.red == 1.0f ? 2 : channel.green == 1.0f ? 1 : 0);
  } else {
    cv::Mat weighted;
    cv::transform(*colour, weighted,
                  cv::Matx13f(static_cast<float>(channel.blue * scale),
                              static_cast<float>(channel.green * scale),
                              static_cast<float>(channel.red * scale)));
    weighted.convertTo(out, CV_8U);
  }
}

void BM_pixel_conversion(benchmark::State& state) {
  const ConversionCase& c = kCases[state.range(0)];
  state.SetLabel(c.name);
  const hal::LaserChannel channel = hal::parse_laser_channel(c.channel);
  const hal::PixelConverter converter(c.format, kWidth, kHeight, channel);
  std::vector<std::uint8_t> buffer = camera_buffer(c.format);
  std::vector<std::uint8_t> out(static_cast<std::size_t>(kWidth) * kHeight);
  for (auto _ : state) {
    converter.convert(buffer.data(), converter.row_bytes(), out.data(), kWidth);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  cv::Mat bgr, reference;
  opencv_reference(c, channel, wrap(c, buffer), bgr, reference);
  const cv::Mat ours(kHeight, kWidth, CV_8UC1, out.data());
  state.counters["differ"] = cv::countNonZero(ours != reference) / double(kWidth * kHeight);
  state.SetItemsProcessed(state.iterations() * kWidth * kHeight);
}
BENCHMARK(BM_pixel_conversion)->DenseRange(0, std::size(kCases) - 1)->Unit(benchmark::kMillisecond);

void BM_pixel_reference_opencv(benchmark::State& state) {
  const ConversionCase& c = kCases[state.range(0)];
  state.SetLabel(c.name);
  const hal::LaserChannel channel = hal::parse_laser_channel(c.channel);
  std::vector<std::uint8_t> buffer = camera_buffer(c.format);
  const cv::Mat in = wrap(c, buffer);
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  cv::Mat bgr, out;
  for (auto _ : state) {
    opencv_reference(c, channel, in, bgr, out);
    benchmark::DoNotOptimize(out.data);
    benchmark::ClobberMemory();
  }
  cv::setNumThreads(threads);
  state.SetItemsProcessed(state.iterations() * kWidth * kHeight);
}
BENCHMARK(BM_pixel_reference_opencv)
    ->DenseRange(0, std::size(kCases) - 1)
    ->Unit(benchmark::kMillisecond);

}  // namespace
