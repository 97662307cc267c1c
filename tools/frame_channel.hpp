#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "hal/laser_channel.hpp"

namespace laserline::tools {

// A frame read from a file, a video or a log, as the detectors see it: mono8 of the laser's
// channel. Mono frames are taken as they are (grey + alpha: the grey); colour frames (OpenCV's
// BGR or BGRA order) give the weighted sum of `channel`, clipped to 0..255, and 255 where a
// positively weighted colour is clipped (as hal::PixelConverter gives camera frames: a saturated
// laser's white core); 16-bit frames are scaled from the range of `sample_bits` bits (16: all of
// it; 12: a 12-bit camera's 0..4095, the larger samples taken as 255) onto 0..255. A colour counts
// as clipped at `clipped_from` or above (8-bit units; the detector's saturation_level): files are
// processed images, whose clipped samples often come out a few levels below 255 (white balance
// after the sensor clipped, lossy compression); so does a pixel whose every colour is within 5
// levels of it (white: clipped, its noise straddling the level). False with a one-line reason in
// `problem` for an empty image or a pixel type the detectors cannot take.
bool to_laser_mono8(const cv::Mat& raw, const hal::LaserChannel& channel, int clipped_from,
                    int sample_bits, cv::Mat& out, std::string& problem);

// The bits a frame's samples use: 8 for an 8-bit frame; for a 16-bit one the fewest of 8, 10, 12,
// 14 and 16 that hold its largest sample (cameras of 10, 12 and 14 bits store their samples in
// the low bits of 16-bit files).
int significant_bits(const cv::Mat& raw);

// Why the bytes of an encoded image are not a whole image, or "" when they are (as far as can be
// told without decoding): a JPEG must reach its end-of-image marker (FF D9) through its segments
// and entropy-coded data, a PNG its IEND chunk with every chunk's CRC right. OpenCV's decoders
// return what they could decode of a cut file (the rest grey or black) with no more than a
// warning, so a damaged frame would look like a good one. Other formats: "" (their decoder says).
std::string encoded_image_damage(const std::vector<std::uint8_t>& bytes);

// Reads an image file as cv::imread(path, cv::IMREAD_UNCHANGED) does, refusing one that
// encoded_image_damage() finds damaged. False with a one-line reason (the file not named).
bool read_image_file(const std::string& path, cv::Mat& out, std::string& problem);

}  // namespace laserline::tools
