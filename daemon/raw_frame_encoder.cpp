#include "daemon/raw_frame_encoder.hpp"

#include <algorithm>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

namespace laserline::daemon {

std::int8_t image_compression_code(ImageCompression c) {
  switch (c) {
    case ImageCompression::kNone:
      return laserline::image_t::COMPRESSION_NONE;
    case ImageCompression::kZlib:
      return laserline::image_t::COMPRESSION_ZLIB;
    case ImageCompression::kPng:
      return laserline::image_t::COMPRESSION_PNG;
    case ImageCompression::kJpeg:
      return laserline::image_t::COMPRESSION_JPEG;
  }
  return laserline::image_t::COMPRESSION_NONE;
}

RawFrameEncoder::RawFrameEncoder(const RawFrameOptions& options, const hal::FrameFormat& format)
    : options_(with_raw_frame_region(options, format)), format_(format) {
  if (const std::string problem = raw_frame_region_problem(options, format); !problem.empty()) {
    throw std::invalid_argument("RawFrameEncoder: " + problem);
  }
  out_width_ = options_.roi_width / options_.downscale;
  out_height_ = options_.roi_height / options_.downscale;
  const std::size_t out_bytes = static_cast<std::size_t>(out_width_) * out_height_;
  scaled_.assign(out_bytes, 0);
  if (options_.compression == ImageCompression::kZlib) {
    zlib_ready_ = deflateInit(&zlib_, options_.zlib_level) == Z_OK;
    packed_.assign(deflateBound(&zlib_, static_cast<uLong>(out_bytes)), 0);
  } else {
    // PNG/JPEG of noise can exceed the raw size a little.
    packed_.reserve(out_bytes + out_bytes / 8 + 4096);
  }
}

RawFrameEncoder::~RawFrameEncoder() {
  if (zlib_ready_) deflateEnd(&zlib_);
}

const std::uint8_t* RawFrameEncoder::region(const ImageSlot& slot, int* stride) {
  const std::uint8_t* roi = slot.pixels.data() +
                            static_cast<std::size_t>(options_.roi_y) * format_.stride +
                            static_cast<std::size_t>(options_.roi_x);
  const int k = options_.downscale;
  if (k == 1 && options_.roi_width == format_.width && options_.roi_height == format_.height) {
    *stride = format_.stride;
    return roi;  // the whole frame as it is
  }
  const int area = k * k;
  for (int y = 0; y < out_height_; ++y) {
    std::uint8_t* out = scaled_.data() + static_cast<std::size_t>(y) * out_width_;
    const std::uint8_t* in = roi + static_cast<std::size_t>(y) * k * format_.stride;
    for (int x = 0; x < out_width_; ++x) {
      unsigned sum = 0;
      for (int dy = 0; dy < k; ++dy) {
        const std::uint8_t* row = in + static_cast<std::size_t>(dy) * format_.stride + x * k;
        for (int dx = 0; dx < k; ++dx)
          sum += row[dx];
      }
      out[x] = static_cast<std::uint8_t>((sum + area / 2) / area);
    }
  }
  *stride = out_width_;
  return scaled_.data();
}

bool RawFrameEncoder::encode(const ImageSlot& slot, laserline::image_t* out) {
  int stride = 0;
  const std::uint8_t* pixels = region(slot, &stride);
  out->width = out_width_;
  out->height = out_height_;
  out->row_stride = out_width_;
  out->roi_x = options_.roi_x;
  out->roi_y = options_.roi_y;
  out->downscale = static_cast<std::int8_t>(options_.downscale);
  out->pixelformat = laserline::image_t::PIXEL_FORMAT_GRAY;
  out->compression = image_compression_code(options_.compression);
  const std::size_t raw_bytes = static_cast<std::size_t>(out_width_) * out_height_;

  const cv::Mat view(out_height_, out_width_, CV_8UC1, const_cast<std::uint8_t*>(pixels),
                     static_cast<std::size_t>(stride));
  switch (options_.compression) {
    case ImageCompression::kNone: {
      out->data.resize(raw_bytes);  // within the capacity reserved by the publisher
      for (int y = 0; y < out_height_; ++y) {
        std::memcpy(out->data.data() + static_cast<std::size_t>(y) * out_width_,
                    pixels + static_cast<std::size_t>(y) * stride,
                    static_cast<std::size_t>(out_width_));
      }
      break;
    }
    case ImageCompression::kZlib: {
      if (!zlib_ready_) return false;
      // zlib wants the rows contiguous: the full frame is (stride == width), a region is packed.
      const std::uint8_t* input = pixels;
      if (stride != out_width_) {
        for (int y = 0; y < out_height_; ++y) {
          std::memcpy(scaled_.data() + static_cast<std::size_t>(y) * out_width_,
                      pixels + static_cast<std::size_t>(y) * stride,
                      static_cast<std::size_t>(out_width_));
        }
        input = scaled_.data();
      }
      deflateReset(&zlib_);
      zlib_.next_in = const_cast<Bytef*>(input);
      zlib_.avail_in = static_cast<uInt>(raw_bytes);
      zlib_.next_out = packed_.data();
      zlib_.avail_out = static_cast<uInt>(packed_.size());
      if (deflate(&zlib_, Z_FINISH) != Z_STREAM_END) return false;
      out->data.resize(zlib_.total_out);
      std::memcpy(out->data.data(), packed_.data(), zlib_.total_out);
      break;
    }
    case ImageCompression::kPng:
    case ImageCompression::kJpeg: {
      const bool png = options_.compression == ImageCompression::kPng;
      // PNG level 1: speed over size, as for zlib.
      const std::vector<int> params =
          png ? std::vector<int>{cv::IMWRITE_PNG_COMPRESSION, 1}
              : std::vector<int>{cv::IMWRITE_JPEG_QUALITY, options_.jpeg_quality};
      if (!cv::imencode(png ? ".png" : ".jpg", view, packed_, params)) return false;
      out->data.assign(packed_.begin(), packed_.end());
      break;
    }
  }
  out->size = static_cast<std::int32_t>(out->data.size());
  return true;
}

}  // namespace laserline::daemon
