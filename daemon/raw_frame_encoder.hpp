#pragma once

#include <zlib.h>
#include <laserline/image_t.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/frame_slots.hpp"
#include "hal/frame.hpp"

namespace laserline::daemon {

// Turns a full raw frame into the laserline.image_t that goes out on LASERLINE_IMAGE: region of
// interest, block-mean downscale, then compression (zlib, PNG or JPEG, stated in the message).
// Buffers and the zlib stream are made at construction, so none and zlib allocate nothing per
// frame; PNG and JPEG go through OpenCV's encoder, which allocates (the image thread is not on
// the frame path). Thread context: the image thread only.
class RawFrameEncoder {
 public:
  // Throws std::invalid_argument when raw_frame_region_problem() is not empty.
  RawFrameEncoder(const RawFrameOptions& options, const hal::FrameFormat& format);
  ~RawFrameEncoder();
  RawFrameEncoder(const RawFrameEncoder&) = delete;
  RawFrameEncoder& operator=(const RawFrameEncoder&) = delete;

  // Fills *out (sized at construction: no allocation for none/zlib). False if compression failed.
  bool encode(const ImageSlot& slot, laserline::image_t* out);

  int out_width() const { return out_width_; }
  int out_height() const { return out_height_; }

 private:
  const std::uint8_t* region(const ImageSlot& slot, int* stride);

  RawFrameOptions options_;
  hal::FrameFormat format_;
  int out_width_ = 0;
  int out_height_ = 0;
  std::vector<std::uint8_t> scaled_;  // ROI + downscale result, packed rows
  std::vector<std::uint8_t> packed_;  // compression output
  z_stream zlib_{};
  bool zlib_ready_ = false;
};

// The message's compression constant for an option.
std::int8_t image_compression_code(ImageCompression c);

}  // namespace laserline::daemon
