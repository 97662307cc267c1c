// Frames from files as the detectors see them: the laser's channel of colour frames, mono and
// 16-bit frames, against values computed by hand.
#include "tools/frame_channel.hpp"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace laserline::tools {
namespace {

cv::Mat convert(const cv::Mat& raw, const std::string& channel, int clipped_from = 255,
                int sample_bits = 16) {
  cv::Mat out;
  std::string problem;
  EXPECT_TRUE(to_laser_mono8(raw, hal::parse_laser_channel(channel), clipped_from, sample_bits, out,
                             problem))
      << problem;
  EXPECT_EQ(out.type(), CV_8UC1);
  return out;
}

TEST(FrameChannel, ColourChannels) {
  // One pixel B = 10, G = 100, R = 200 and one white pixel; OpenCV's order is BGR.
  cv::Mat bgr(1, 2, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = {10, 100, 200};
  bgr.at<cv::Vec3b>(0, 1) = {180, 180, 180};
  EXPECT_EQ(convert(bgr, "red").at<std::uint8_t>(0, 0), 200);
  EXPECT_EQ(convert(bgr, "green").at<std::uint8_t>(0, 0), 100);
  EXPECT_EQ(convert(bgr, "blue").at<std::uint8_t>(0, 0), 10);
  // 0.299 * 200 + 0.587 * 100 + 0.114 * 10 = 119.64
  EXPECT_EQ(convert(bgr, "grey").at<std::uint8_t>(0, 0), 120);
  // red - (green + blue) / 2: 200 - 55 = 145 on the red pixel, 0 on white light.
  const cv::Mat difference = convert(bgr, "red - (green + blue) / 2");
  EXPECT_EQ(difference.at<std::uint8_t>(0, 0), 145);
  EXPECT_EQ(difference.at<std::uint8_t>(0, 1), 0);
  // Clipped below 0 and above 255.
  EXPECT_EQ(convert(bgr, "blue - red").at<std::uint8_t>(0, 0), 0);
  EXPECT_EQ(convert(bgr, "2 * red").at<std::uint8_t>(0, 0), 255);
  // An alpha channel changes nothing.
  cv::Mat bgra;
  cv::merge(std::vector<cv::Mat>{bgr, cv::Mat(1, 2, CV_8UC1, cv::Scalar(7))}, bgra);
  EXPECT_EQ(convert(bgra, "red").at<std::uint8_t>(0, 0), 200);
  EXPECT_EQ(convert(bgra, "red - (green + blue) / 2").at<std::uint8_t>(0, 0), 145);
}

// A laser that saturates the sensor is white at its core (every colour clipped): a weighted
// difference takes it for the laser where its colour is clipped, as the cameras' conversion does,
// not for white light.
TEST(FrameChannel, ClippedLaserColourGives255) {
  cv::Mat bgr(1, 4, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = {255, 255, 255};  // the clipped white core
  bgr.at<cv::Vec3b>(0, 1) = {90, 120, 255};   // red clipped, a fringe
  bgr.at<cv::Vec3b>(0, 2) = {254, 254, 254};  // bright white light, not clipped
  bgr.at<cv::Vec3b>(0, 3) = {255, 255, 40};   // blue and green clipped, red not
  const cv::Mat difference = convert(bgr, "red - (green + blue) / 2");
  EXPECT_EQ(difference.at<std::uint8_t>(0, 0), 255);
  EXPECT_EQ(difference.at<std::uint8_t>(0, 1), 255);
  EXPECT_EQ(difference.at<std::uint8_t>(0, 2), 0);
  EXPECT_EQ(difference.at<std::uint8_t>(0, 3), 0);
  cv::Mat deep(1, 2, CV_16UC3);
  deep.at<cv::Vec3w>(0, 0) = {65535, 65535, 65535};
  deep.at<cv::Vec3w>(0, 1) = {60000, 60000, 60000};
  const cv::Mat deep_difference = convert(deep, "red - (green + blue) / 2");
  EXPECT_EQ(deep_difference.at<std::uint8_t>(0, 0), 255);
  EXPECT_EQ(deep_difference.at<std::uint8_t>(0, 1), 0);
  // From a level below the top (the detector's saturation_level): red at 251 is clipped, at 249
  // it is not; white light at 251 in every colour is taken for clipped too, and so is white whose
  // every colour is within 5 levels of it (a clipped core's noise straddles the level: without
  // this, red - (green + blue) / 2 turns 249 - 251 into black gaps in a saturated line).
  cv::Mat near(1, 5, CV_8UC3);
  near.at<cv::Vec3b>(0, 0) = {240, 245, 251};
  near.at<cv::Vec3b>(0, 1) = {240, 245, 249};
  near.at<cv::Vec3b>(0, 2) = {251, 251, 251};
  near.at<cv::Vec3b>(0, 3) = {251, 251, 249};
  near.at<cv::Vec3b>(0, 4) = {251, 244, 249};  // green more than 5 below: not white
  const cv::Mat from_250 = convert(near, "red - (green + blue) / 2", 250);
  EXPECT_EQ(from_250.at<std::uint8_t>(0, 0), 255);
  EXPECT_EQ(from_250.at<std::uint8_t>(0, 1), 7);  // 249 - 242.5, rounded half up
  EXPECT_EQ(from_250.at<std::uint8_t>(0, 2), 255);
  EXPECT_EQ(from_250.at<std::uint8_t>(0, 3), 255);
  EXPECT_EQ(from_250.at<std::uint8_t>(0, 4), 2);  // 249 - 247.5, rounded half up
  EXPECT_EQ(convert(near, "red - (green + blue) / 2").at<std::uint8_t>(0, 0), 9);  // 251 - 242.5
}

TEST(FrameChannel, MonoAnd16Bit) {
  const cv::Mat grey(1, 1, CV_8UC1, cv::Scalar(77));
  EXPECT_EQ(convert(grey, "red").at<std::uint8_t>(0, 0), 77);  // mono: as it is
  cv::Mat grey_alpha(1, 1, CV_8UC2, cv::Scalar(66, 255));
  EXPECT_EQ(convert(grey_alpha, "green").at<std::uint8_t>(0, 0), 66);
  const cv::Mat deep(1, 1, CV_16UC1, cv::Scalar(65535));
  EXPECT_EQ(convert(deep, "green").at<std::uint8_t>(0, 0), 255);
  cv::Mat deep_colour(1, 1, CV_16UC3, cv::Scalar(0, 0, 32896));  // red at half range
  EXPECT_EQ(convert(deep_colour, "red").at<std::uint8_t>(0, 0), 128);
  EXPECT_EQ(convert(deep_colour, "red - green / 2").at<std::uint8_t>(0, 0), 128);
}

// A 12-bit camera's 16-bit file (samples 0..4095): its range onto 0..255, larger samples at the
// top; the bits found from the largest sample.
TEST(FrameChannel, SixteenBitFilesOfFewerBits) {
  cv::Mat twelve(1, 4, CV_16UC1);
  twelve.at<std::uint16_t>(0, 0) = 4095;
  twelve.at<std::uint16_t>(0, 1) = 2048;  // 127.5 -> 128
  twelve.at<std::uint16_t>(0, 2) = 16;    // 0.996 -> 1
  twelve.at<std::uint16_t>(0, 3) = 0;
  EXPECT_EQ(significant_bits(twelve), 12);
  const cv::Mat read = convert(twelve, "green", 255, 12);
  EXPECT_EQ(read.at<std::uint8_t>(0, 0), 255);
  EXPECT_EQ(read.at<std::uint8_t>(0, 1), 128);
  EXPECT_EQ(read.at<std::uint8_t>(0, 2), 1);
  EXPECT_EQ(read.at<std::uint8_t>(0, 3), 0);
  EXPECT_EQ(convert(twelve, "green", 255, 16).at<std::uint8_t>(0, 0), 16);   // 4095 / 257
  EXPECT_EQ(convert(twelve, "green", 255, 10).at<std::uint8_t>(0, 1), 255);  // beyond 10 bits
  cv::Mat colour(1, 1, CV_16UC3, cv::Scalar(0, 0, 1023));  // red at the top of 10 bits
  EXPECT_EQ(significant_bits(colour), 10);
  EXPECT_EQ(convert(colour, "red", 255, 10).at<std::uint8_t>(0, 0), 255);
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_16UC1, cv::Scalar(255))), 8);
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_16UC1, cv::Scalar(16383))), 14);
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_16UC1, cv::Scalar(16384))), 16);
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_8UC1, cv::Scalar(3))), 8);
  // An opaque alpha channel does not count.
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_16UC4, cv::Scalar(4000, 100, 5, 65535))), 12);
  EXPECT_EQ(significant_bits(cv::Mat(2, 2, CV_16UC2, cv::Scalar(1000, 65535))), 10);
}

TEST(FrameChannel, Problems) {
  cv::Mat out;
  std::string problem;
  EXPECT_FALSE(to_laser_mono8(cv::Mat(), {}, 255, 16, out, problem));
  EXPECT_EQ(problem, "empty image");
  EXPECT_FALSE(to_laser_mono8(cv::Mat(2, 2, CV_32FC1), {}, 255, 16, out, problem));
  EXPECT_EQ(problem, "unsupported pixel type (only 8 and 16 bit unsigned integers)");
  EXPECT_FALSE(to_laser_mono8(cv::Mat(2, 2, CV_8UC(5)), {}, 255, 16, out, problem));
  EXPECT_EQ(problem, "unsupported number of channels (5)");
}

}  // namespace
}  // namespace laserline::tools
