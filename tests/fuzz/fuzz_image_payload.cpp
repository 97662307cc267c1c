// libFuzzer: image_t pixels (messages::unpack_image): a header of 12 bytes picks the frame's
// size, stride, pixel format and compression; the rest is the payload. Uncompressed, zlib, PNG
// and JPEG payloads must be refused or unpacked to exactly the frame the header says.
#include <opencv2/imgcodecs.hpp>

#include "lcmtypes/checked_decode.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr std::size_t kHeader = 12;
  if (size < kHeader) return 0;
  laserline::image_t m;
  m.width = static_cast<std::int16_t>(data[0] | (data[1] << 8));
  m.height = static_cast<std::int16_t>(data[2] | (data[3] << 8));
  m.row_stride = static_cast<std::int32_t>(
      static_cast<std::uint32_t>(data[4]) | (static_cast<std::uint32_t>(data[5]) << 8) |
      (static_cast<std::uint32_t>(data[6]) << 16) | (static_cast<std::uint32_t>(data[7]) << 24));
  static constexpr std::int32_t kFormats[] = {laserline::image_t::PIXEL_FORMAT_GRAY,
                                              laserline::image_t::PIXEL_FORMAT_LE_GRAY16,
                                              laserline::image_t::PIXEL_FORMAT_BE_GRAY16, 12345};
  m.pixelformat = kFormats[data[8] % 4];
  m.compression = static_cast<std::int8_t>(data[9] % 5);
  const int flags = data[10] % 2 == 0 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_UNCHANGED;
  m.data.assign(data + kHeader, data + size);
  m.size = static_cast<std::int32_t>(m.data.size());
  laserline::messages::Limits limits;
  limits.max_width = 1024;
  limits.max_height = 1024;
  cv::Mat out;
  std::string problem;
  if (!laserline::messages::unpack_image(m, limits, flags, &out, &problem)) {
    if (problem.empty() || !out.empty()) std::abort();
    return 0;
  }
  if (out.cols != m.width || out.rows != m.height) std::abort();
  return 0;
}
