#include "tools/frame_channel.hpp"

#include <algorithm>

#include <zlib.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hal/pixel_conversion.hpp"

namespace laserline::tools {

namespace {

constexpr const char* kCutShort = "cut short";

std::string at_byte(std::size_t offset) {
  return " at byte " + std::to_string(offset);
}

// JPEG (ITU T.81 B.1): markers FF xx, segments with a 16-bit length, entropy-coded data after each
// start of scan up to the next marker that is not a stuffed byte (FF 00) or a restart (FF D0..D7).
std::string jpeg_damage(const std::vector<std::uint8_t>& d) {
  const std::size_t n = d.size();
  auto cut = [](const char* where) {
    return std::string(kCutShort) + where + ": no end-of-image marker (FF D9)";
  };
  std::size_t i = 2;  // after the start-of-image marker
  while (true) {
    if (i >= n) return cut("");
    if (d[i] != 0xFF) return "damaged: a segment expected" + at_byte(i);
    while (i < n && d[i] == 0xFF)
      ++i;  // fill bytes
    if (i >= n) return cut("");
    const std::uint8_t marker = d[i++];
    if (marker == 0xD9) return "";
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no length
    if (i + 2 > n) return cut(" in a segment");
    const std::size_t length = (std::size_t{d[i]} << 8) | d[i + 1];
    if (length < 2) return "damaged: a segment of length " + std::to_string(length) + at_byte(i);
    if (i + length > n) return cut(" in a segment");
    i += length;
    if (marker != 0xDA) continue;
    while (true) {  // entropy-coded data
      if (i + 1 >= n) return cut(" in the image data");
      if (d[i] == 0xFF && d[i + 1] != 0x00 && d[i + 1] != 0xFF &&
          !(d[i + 1] >= 0xD0 && d[i + 1] <= 0xD7)) {
        break;
      }
      ++i;
    }
  }
}

std::uint32_t big_endian_32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         p[3];
}

// PNG: the signature, then chunks (length, type, data, CRC of type and data) up to IEND.
std::string png_damage(const std::vector<std::uint8_t>& d) {
  const std::size_t n = d.size();
  std::size_t i = 8;
  while (true) {
    if (i + 8 > n) return std::string(kCutShort) + ": no IEND chunk";
    const std::size_t length = big_endian_32(&d[i]);
    const std::string type(reinterpret_cast<const char*>(&d[i + 4]), 4);
    if (length > n || i + 12 + length > n) {
      return std::string(kCutShort) + ": chunk " + type + at_byte(i) + " runs past the end";
    }
    const auto crc = crc32(crc32(0L, Z_NULL, 0), &d[i + 4], static_cast<uInt>(length + 4));
    if (crc != big_endian_32(&d[i + 8 + length])) {
      return "damaged: chunk " + type + at_byte(i) + " fails its CRC";
    }
    if (type == "IEND") return "";
    i += 12 + length;
  }
}

}  // namespace

std::string encoded_image_damage(const std::vector<std::uint8_t>& bytes) {
  static constexpr std::uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (bytes.size() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF) {
    return jpeg_damage(bytes);
  }
  if (bytes.size() >= 8 && std::equal(std::begin(kPng), std::end(kPng), bytes.begin())) {
    return png_damage(bytes);
  }
  return "";
}

bool read_image_file(const std::string& path, cv::Mat& out, std::string& problem) {
  out.release();
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    problem = std::string("cannot be read: ") + std::strerror(errno);
    return false;
  }
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
  if (in.bad()) {
    problem = std::string("read error: ") + std::strerror(errno);
    return false;
  }
  if (const std::string damage = encoded_image_damage(bytes); !damage.empty()) {
    problem = "damaged image (" + damage + ")";
    return false;
  }
  try {
    out = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    out.release();
  }
  if (out.empty()) {
    problem = "not a readable image (corrupt or unsupported format)";
    return false;
  }
  return true;
}

int significant_bits(const cv::Mat& raw) {
  if (raw.depth() != CV_16U || raw.empty()) return 8;
  // Grey + alpha and BGRA: the alpha channel (often all 65535) says nothing of the camera.
  const int colours =
      raw.channels() == 2 || raw.channels() == 4 ? raw.channels() - 1 : raw.channels();
  double largest = 0;
  for (int c = 0; c < colours; ++c) {
    cv::Mat plane;
    cv::extractChannel(raw, plane, c);
    double most = 0;
    cv::minMaxLoc(plane, nullptr, &most);
    largest = std::max(largest, most);
  }
  for (const int bits : {8, 10, 12, 14})
    if (largest <= static_cast<double>((1 << bits) - 1)) return bits;
  return 16;
}

bool to_laser_mono8(const cv::Mat& raw, const hal::LaserChannel& channel, int clipped_from,
                    int sample_bits, cv::Mat& out, std::string& problem) {
  constexpr int kWhiteMargin = 5;
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
  // 16 bit: the range of sample_bits onto 0..255 (beyond it: 255).
  const double scale = raw.depth() == CV_16U
                           ? 255.0 / static_cast<double>((1 << std::clamp(sample_bits, 8, 16)) - 1)
                           : 1.0;
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
  // A weighted sum: through the cameras' own conversion (hal::PixelConverter), so that a pixel
  // whose positively weighted colour is clipped gives 255 here too. (A saturated laser is white
  // at its core: red - (green + blue) / 2 would make it a dark gap between two red fringes, and
  // the line would be found on a fringe, pixels off its centre.)
  cv::Mat planes[4];
  cv::split(raw, planes);
  // Blue, green, red as OpenCV orders them; a positively weighted one at clipped_from or above is
  // raised to 255, where the conversion's rule takes it.
  const float weights[3] = {channel.blue, channel.green, channel.red};
  for (int i = 0; i < 3; ++i) {
    // 16 bit: onto 0..255 first; the top codes become 255, clipped as 8-bit samples are.
    if (scale != 1.0) planes[i].convertTo(planes[i], CV_8U, scale);
  }
  cv::Mat clipped;
  if (clipped_from < 255) {
    // Every colour within kWhiteMargin of the level: white, clipped (a bright laser's core and
    // bloom on a white surface, its noise straddling the level); a colour difference there is
    // noise about 0, dark gaps in the line.
    const int near_top = std::max(clipped_from - kWhiteMargin, 0);
    clipped = (planes[0] >= near_top) & (planes[1] >= near_top) & (planes[2] >= near_top);
  }
  for (int i = 0; i < 3; ++i) {
    if (weights[i] > 0.0f && clipped_from < 255) {
      planes[i] = planes[i].clone();
      planes[i].setTo(255, (planes[i] >= clipped_from) | clipped);
    }
  }
  cv::Mat bgr;
  cv::merge(planes, 3, bgr);
  const hal::PixelConverter converter({hal::PixelLayout::kBgr, 8}, bgr.cols, bgr.rows, channel);
  out.create(bgr.rows, bgr.cols, CV_8UC1);
  converter.convert(bgr.data, bgr.step, out.data, out.step);
  return true;
}

}  // namespace laserline::tools
