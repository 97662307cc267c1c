#include "tools/frame_channel.hpp"

#include <opencv2/core.hpp>

namespace laserline::tools {

bool to_laser_mono8(const cv::Mat& raw, const hal::LaserChannel& channel, cv::Mat& out,
                    std::string& problem) {
  if (raw.empty()) {
    problem = "empty image";
    return false;
  }
  if (raw.depth() != CV_8U && raw.depth() != CV_16U) {
    problem = "unsupported pixel type (only 8 and 16 bit unsigned integers)";
    return false;
  }
  const int channels = raw.channels();
  if (channels < 1 || channels > 4) {
    problem = "unsupported number of channels (" + std::to_string(channels) + ")";
    return false;
  }
  // 16 bit: the full range onto 0..255.
  const double scale = raw.depth() == CV_16U ? 255.0 / 65535.0 : 1.0;
  if (channels <= 2) {
    cv::Mat grey;
    if (channels == 2) {
      cv::extractChannel(raw, grey, 0);  // grey + alpha
    } else {
      grey = raw;
    }
    if (scale != 1.0) {
      grey.convertTo(out, CV_8U, scale);
    } else {
      out = grey;
    }
    return true;
  }
  // OpenCV orders colour channels B, G, R (and alpha).
  const int pick = channel.single() ? (channel.red == 1.0f     ? 2
                                       : channel.green == 1.0f ? 1
                                                               : 0)
                                    : -1;
  if (pick >= 0) {
    cv::Mat one;
    cv::extractChannel(raw, one, pick);
    if (scale != 1.0) {
      one.convertTo(out, CV_8U, scale);
    } else {
      out = one;
    }
    return true;
  }
  cv::Matx<float, 1, 4> weights(static_cast<float>(channel.blue * scale),
                                static_cast<float>(channel.green * scale),
                                static_cast<float>(channel.red * scale), 0.0f);
  cv::Mat mixed;
  if (channels == 3) {
    cv::transform(raw, mixed, cv::Matx<float, 1, 3>(weights(0), weights(1), weights(2)));
  } else {
    cv::transform(raw, mixed, weights);
  }
  // transform() saturates to the input depth; a 16-bit result is then scaled already (weights).
  mixed.convertTo(out, CV_8U);
  return true;
}

}  // namespace laserline::tools
