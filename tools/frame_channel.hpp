#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "hal/laser_channel.hpp"

namespace laserline::tools {

// A frame read from a file, a video or a log, as the detectors see it: mono8 of the laser's
// channel. Mono frames are taken as they are (grey + alpha: the grey); colour frames (OpenCV's
// BGR or BGRA order) give the weighted sum of `channel`, clipped to 0..255; 16-bit frames are
// scaled from their full range onto 0..255. False with a one-line reason in `problem` for an
// empty image or a pixel type the detectors cannot take.
bool to_laser_mono8(const cv::Mat& raw, const hal::LaserChannel& channel, cv::Mat& out,
                    std::string& problem);

}  // namespace laserline::tools
