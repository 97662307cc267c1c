#include "lcmtypes/checked_decode.hpp"

#include <zlib.h>

#include <cstring>
#include <exception>
#include <opencv2/imgcodecs.hpp>

#include "lcmtypes/big_endian.hpp"

namespace laserline::messages {

namespace {

using laserline::image_t;

// Encoded sizes of fixed fields (LCM: big-endian, boolean one byte).
constexpr std::size_t kI8 = 1, kBool = 1, kI16 = 2, kI32 = 4, kF32 = 4, kI64 = 8, kF64 = 8;
constexpr std::size_t kPointBytes = kI16 + kF32 + kF32 + kI32 + kBool + 3 * kF32;
constexpr std::size_t kMaxProblemKinds = 64;

// Walks an encoded message field by field without building it.
class Walker {
 public:
  Walker(const void* data, std::size_t size, std::string* problem)
      : p_(static_cast<const std::uint8_t*>(data)), size_(size), problem_(problem) {}

  bool fail(const std::string& what) {
    if (problem_ != nullptr) *problem_ = what;
    return false;
  }
  std::size_t remaining() const { return size_ - pos_; }
  std::size_t pos() const { return pos_; }

  bool skip(std::size_t bytes, const char* field) {
    if (bytes > remaining()) {
      return fail(std::string(field) + " at byte " + std::to_string(pos_) + " runs past the end (" +
                  std::to_string(size_) + " bytes)");
    }
    pos_ += bytes;
    return true;
  }
  bool int32(std::int32_t* v, const char* field) {
    if (kI32 > remaining()) return skip(kI32, field);
    *v = static_cast<std::int32_t>(static_cast<std::uint32_t>(big_endian(p_ + pos_, 4)));
    pos_ += kI32;
    return true;
  }
  bool hash(std::int64_t expected, const char* type) {
    if (size_ < kI64) {
      return fail(std::to_string(size_) + " bytes are too short for a " + std::string(type));
    }
    if (static_cast<std::int64_t>(big_endian(p_, 8)) != expected) {
      return fail(std::string("not a ") + type + " (another type's fingerprint)");
    }
    pos_ = kI64;
    return true;
  }
  // An LCM string: int32 length counting the terminating NUL, the bytes, the NUL.
  bool string(const char* field, std::int32_t max_bytes) {
    const std::size_t at = pos_;
    std::int32_t length = 0;
    if (!int32(&length, field)) return false;
    if (length < 1 || length - 1 > max_bytes) {
      return fail(std::string(field) + " at byte " + std::to_string(at) + ": length " +
                  std::to_string(length) + " outside 1.." + std::to_string(max_bytes + 1));
    }
    if (!skip(static_cast<std::size_t>(length), field)) return false;
    // One NUL, at the end: anything else does not encode back to the same bytes.
    const std::uint8_t* text = p_ + pos_ - static_cast<std::size_t>(length);
    if (std::memchr(text, 0, static_cast<std::size_t>(length)) != text + length - 1) {
      return fail(std::string(field) + " at byte " + std::to_string(at) +
                  ": not one NUL-terminated string");
    }
    return true;
  }
  bool count(const char* field, std::int64_t max, std::size_t element_bytes, std::int32_t* n) {
    const std::size_t at = pos_;
    if (!int32(n, field)) return false;
    if (*n < 0 || *n > max) {
      return fail(std::string(field) + " at byte " + std::to_string(at) + ": " +
                  std::to_string(*n) + " outside 0.." + std::to_string(max));
    }
    if (static_cast<std::size_t>(*n) * element_bytes > remaining()) {
      return fail(std::string(field) + " at byte " + std::to_string(at) + ": " +
                  std::to_string(*n) + " elements (" +
                  std::to_string(static_cast<std::size_t>(*n) * element_bytes) + " bytes) but " +
                  std::to_string(remaining()) + " bytes remain");
    }
    return skip(static_cast<std::size_t>(*n) * element_bytes, field);
  }
  bool end(const char* type) {
    if (pos_ != size_) {
      return fail(std::to_string(size_ - pos_) + " bytes after the end of the " + type + " (" +
                  std::to_string(pos_) + " of " + std::to_string(size_) + " bytes used)");
    }
    return true;
  }

 private:
  const std::uint8_t* p_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::string* problem_;
};

// Decodes with lcm-gen's code once the walk has bounded every length.
template <typename Message>
bool generated_decode(const void* data, std::size_t size, Message* out, std::string* problem) {
  try {
    if (out->decode(data, 0, static_cast<int>(size)) == static_cast<int>(size)) return true;
  } catch (const std::exception& e) {
    if (problem != nullptr) *problem = std::string("decode failed: ") + e.what();
    return false;
  }
  if (problem != nullptr) *problem = "does not decode";
  return false;
}

bool walk_profile(Walker& w, const Limits& limits) {
  std::int32_t n = 0;
  return w.hash(laserline::profile_t::getHash(), "laserline.profile_t") &&
         w.skip(3 * kI64 + kBool + 2 * kI32, "header") &&
         w.string("detector", limits.max_string_bytes) &&
         w.skip(kI64 + kBool + kI8 + 6 * kF64, "search axes") &&
         w.count("num_points", limits.max_points, kPointBytes, &n) && w.skip(kI64, "instance_id") &&
         w.skip(2 * kF64, "exposure_us, gain_db") && w.skip(kI64, "calibration_id") &&
         w.end("laserline.profile_t");
}

bool walk_calibration(Walker& w) {
  return w.hash(laserline::calibration_t::getHash(), "laserline.calibration_t") &&
         w.skip(2 * kI64, "utime, calibration_id") && w.skip(2 * kI32, "width, height") &&
         w.skip(4 * kF64, "fx, fy, cx, cy") && w.skip(5 * kF64, "distortion") &&
         w.skip(4 * kF64, "laser_plane") && w.skip(kF64, "sheet_width_m") &&
         w.skip(kI64, "instance_id") && w.end("laserline.calibration_t");
}

bool walk_status(Walker& w, const Limits& limits) {
  return w.hash(laserline::status_t::getHash(), "laserline.status_t") &&
         w.skip(2 * kI64, "utime") && w.string("camera_backend", limits.max_string_bytes) &&
         w.string("detector", limits.max_string_bytes) &&
         w.string("camera_state", limits.max_string_bytes) &&
         // laser_on, laser_switches, 12 frame counters, 9 rates, 3 CPU/budget, 8 camera counters,
         // bad_messages, bad_frames, instance_id.
         w.skip(kBool + kI64 + 12 * kI64 + 2 * kF32 + kI32 + 6 * kF32 + kF32 + kI64 + kF32 +
                    8 * kI64 + 3 * kI64,
                "counters") &&
         w.string("strobe_state", limits.max_string_bytes) &&
         w.skip(kI64, "strobe_unmatched_frames") && w.end("laserline.status_t");
}

bool walk_command(Walker& w, const Limits& limits) {
  const std::int32_t max = limits.max_string_bytes;
  return w.hash(laserline::command_t::getHash(), "laserline.command_t") &&
         w.skip(2 * kI64, "utime, id") && w.string("sender", max) && w.string("name", max) &&
         w.string("value", max) && w.string("token", max) && w.end("laserline.command_t");
}

bool walk_command_ack(Walker& w, const Limits& limits) {
  const std::int32_t max = limits.max_string_bytes;
  return w.hash(laserline::command_ack_t::getHash(), "laserline.command_ack_t") &&
         w.skip(2 * kI64, "utime, id") && w.string("name", max) && w.skip(kBool, "accepted") &&
         w.string("reason", max) && w.string("value", max) && w.string("old_value", max) &&
         w.skip(kI64, "instance_id") && w.end("laserline.command_ack_t");
}

bool walk_image(Walker& w, const Limits& limits) {
  std::int32_t n = 0;
  return w.hash(image_t::getHash(), "laserline.image_t") &&
         w.skip(3 * kI64 + kBool + 4 * kI32 + kI8 + 2 * kI32 + kI8, "header") &&
         w.count("size", limits.max_image_bytes, 1, &n) &&
         w.skip(2 * kF64, "exposure_us, gain_db") && w.end("laserline.image_t");
}

bool png_size(const std::uint8_t* d, std::size_t n, int* width, int* height) {
  static constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n < 24 || std::memcmp(d, kSignature, 8) != 0 || std::memcmp(d + 12, "IHDR", 4) != 0) {
    return false;
  }
  const std::uint64_t w = big_endian(d + 16, 4), h = big_endian(d + 20, 4);
  if (w > 0x7fffffff || h > 0x7fffffff) return false;
  *width = static_cast<int>(w);
  *height = static_cast<int>(h);
  return true;
}

bool jpeg_size(const std::uint8_t* d, std::size_t n, int* width, int* height) {
  if (n < 4 || d[0] != 0xff || d[1] != 0xd8) return false;
  std::size_t pos = 2;
  while (pos + 4 <= n) {
    if (d[pos] != 0xff) return false;
    const std::uint8_t marker = d[pos + 1];
    if (marker == 0xff) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0xd8 || marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) {
      pos += 2;
      continue;
    }
    const std::size_t length = big_endian(d + pos + 2, 2);
    if (length < 2) return false;
    // SOF0..SOF15 except DHT (C4), JPG (C8) and DAC (CC).
    if (marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc) {
      if (pos + 9 > n) return false;
      *height = static_cast<int>(big_endian(d + pos + 5, 2));
      *width = static_cast<int>(big_endian(d + pos + 7, 2));
      return true;
    }
    if (marker == 0xd9 || marker == 0xda) return false;  // end of image or scan before a frame
    pos += 2 + length;
  }
  return false;
}

}  // namespace

std::int64_t message_hash(const void* data, std::size_t size) {
  if (size < kI64) return 0;
  return static_cast<std::int64_t>(big_endian(static_cast<const std::uint8_t*>(data), 8));
}

bool decode(const void* data, std::size_t size, laserline::point_t* out, const Limits&,
            std::string* problem) {
  Walker w(data, size, problem);
  return w.hash(laserline::point_t::getHash(), "laserline.point_t") &&
         w.skip(kPointBytes, "point") && w.end("laserline.point_t") &&
         generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::profile_t* out, const Limits& limits,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_profile(w, limits) && generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::status_t* out, const Limits& limits,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_status(w, limits) && generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::calibration_t* out, const Limits&,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_calibration(w) && generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::command_t* out, const Limits& limits,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_command(w, limits) && generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::command_ack_t* out, const Limits& limits,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_command_ack(w, limits) && generated_decode(data, size, out, problem);
}

bool decode(const void* data, std::size_t size, laserline::image_t* out, const Limits& limits,
            std::string* problem) {
  Walker w(data, size, problem);
  return walk_image(w, limits) && generated_decode(data, size, out, problem);
}

bool compressed_image_size(const std::uint8_t* data, std::size_t size, int* width, int* height) {
  return png_size(data, size, width, height) || jpeg_size(data, size, width, height);
}

bool unpack_image(const image_t& m, const Limits& limits, int imread_flags, cv::Mat* out,
                  std::string* problem) {
  auto fail = [&](const std::string& what) {
    *problem = what;
    out->release();
    return false;
  };
  const std::string frame = std::to_string(m.width) + "x" + std::to_string(m.height);
  if (m.width <= 0 || m.height <= 0 || m.width > limits.max_width || m.height > limits.max_height) {
    return fail("frame size " + frame + " outside 1x1.." + std::to_string(limits.max_width) + "x" +
                std::to_string(limits.max_height));
  }
  if (static_cast<std::size_t>(m.size) != m.data.size()) {
    return fail("size " + std::to_string(m.size) + " differs from the " +
                std::to_string(m.data.size()) + " bytes of data");
  }
  try {
    if (m.compression == image_t::COMPRESSION_PNG || m.compression == image_t::COMPRESSION_JPEG) {
      int w = 0, h = 0;
      if (!compressed_image_size(m.data.data(), m.data.size(), &w, &h)) {
        return fail(std::string(m.compression == image_t::COMPRESSION_PNG ? "png" : "jpeg") +
                    " data have no readable header");
      }
      if (w != m.width || h != m.height) {
        return fail("compressed image is " + std::to_string(w) + "x" + std::to_string(h) +
                    ", the message says " + frame);
      }
      *out = cv::imdecode(cv::Mat(1, static_cast<int>(m.data.size()), CV_8UC1,
                                  const_cast<std::uint8_t*>(m.data.data())),
                          imread_flags);
      if (out->empty() || out->cols != m.width || out->rows != m.height) {
        return fail("compressed data do not decode to a " + frame + " image");
      }
      return true;
    }
    int type = 0, bytes_per_pixel = 0;
    if (m.pixelformat == image_t::PIXEL_FORMAT_GRAY) {
      type = CV_8UC1;
      bytes_per_pixel = 1;
    } else if (m.pixelformat == image_t::PIXEL_FORMAT_LE_GRAY16 ||
               m.pixelformat == image_t::PIXEL_FORMAT_BE_GRAY16) {
      type = CV_16UC1;
      bytes_per_pixel = 2;
    } else {
      return fail("unsupported pixel format " + std::to_string(m.pixelformat));
    }
    const std::int64_t row_bytes = static_cast<std::int64_t>(m.width) * bytes_per_pixel;
    if (m.compression == image_t::COMPRESSION_ZLIB) {
      out->create(m.height, m.width, type);
      const auto want = static_cast<uLongf>(out->total() * out->elemSize());
      uLongf got = want;
      const int z = uncompress(out->data, &got, m.data.data(), static_cast<uLong>(m.data.size()));
      if (z != Z_OK || got != want) {
        return fail("zlib data do not unpack to a " + frame + " frame (" +
                    (z == Z_OK ? std::to_string(got) + " bytes" : std::string(zError(z))) + ")");
      }
    } else if (m.compression == image_t::COMPRESSION_NONE) {
      if (m.row_stride < row_bytes ||
          static_cast<std::int64_t>(m.row_stride) * (m.height - 1) + row_bytes > m.size) {
        return fail("row_stride " + std::to_string(m.row_stride) + " and " +
                    std::to_string(m.size) + " bytes do not hold a " + frame + " frame");
      }
      cv::Mat(m.height, m.width, type, const_cast<std::uint8_t*>(m.data.data()),
              static_cast<std::size_t>(m.row_stride))
          .copyTo(*out);
    } else {
      return fail("unknown compression " + std::to_string(m.compression));
    }
    if (m.pixelformat == image_t::PIXEL_FORMAT_BE_GRAY16) {
      for (int v = 0; v < out->rows; ++v) {
        auto* row = out->ptr<std::uint16_t>(v);
        for (int u = 0; u < out->cols; ++u)
          row[u] = static_cast<std::uint16_t>((row[u] >> 8) | (row[u] << 8));
      }
    }
    return true;
  } catch (const std::exception& e) {
    return fail(std::string("image cannot be decoded: ") + e.what());
  }
}

void ProblemLog::report(const std::string& kind, const std::string& line) {
  ++total_;
  auto it = kinds_.find(kind);
  if (it == kinds_.end()) {
    if (kinds_.size() >= kMaxProblemKinds)
      it = kinds_.try_emplace("(other kinds)").first;
    else
      it = kinds_.try_emplace(kind).first;
  }
  Kind& k = it->second;
  ++k.count;
  const auto now = std::chrono::steady_clock::now();
  if (k.count <= kFirst || now - k.last_line >= kEvery) {
    if (k.unreported > 0) {
      std::fprintf(stderr, "%s%s (and %lld more like it not shown)\n", prefix_.c_str(),
                   line.c_str(), static_cast<long long>(k.unreported));
    } else {
      std::fprintf(stderr, "%s%s\n", prefix_.c_str(), line.c_str());
    }
    if (k.count == kFirst) {
      std::fprintf(stderr, "%sfurther problems like this are reported at most once every %llds\n",
                   prefix_.c_str(), static_cast<long long>(kEvery.count()));
    }
    k.unreported = 0;
    k.last_line = now;
  } else {
    ++k.unreported;
  }
}

}  // namespace laserline::messages
