#pragma once

#include <laserline/calibration_t.hpp>
#include <laserline/command_ack_t.hpp>
#include <laserline/command_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/point_t.hpp>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <string>

namespace laserline::messages {

// What a message of ours may hold. lcm-gen's decode() trusts the lengths in a message (a negative
// string length throws std::length_error, num_points = -1 or image_t.size = 0x7fffffff allocate
// gigabytes), so every message is walked first: each length against these limits and against
// the bytes received, and only then decoded.
struct Limits {
  std::int32_t max_string_bytes = 256;  // detector, camera_backend, camera_state, command_t's and
                                        // command_ack_t's texts (without NUL)
  std::int32_t max_points = 1 << 16;    // per profile (point_t.u is 16 bit)
  std::int64_t max_image_bytes = 64 << 20;  // image_t.data (compressed or not)
  std::int32_t max_width = 16384;           // image_t.width and height, also inside PNG/JPEG
  std::int32_t max_height = 16384;
};

// Each decodes a whole message of `size` bytes into *out. False with a one-line reason in *problem
// (the field and what is wrong, with byte offsets) for a message that is not exactly one valid
// encoding of the type, or that exceeds `limits`; nothing is allocated beyond those limits and
// no exception escapes.
bool decode(const void* data, std::size_t size, laserline::point_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::profile_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::status_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::image_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::calibration_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::command_t* out, const Limits& limits,
            std::string* problem);
bool decode(const void* data, std::size_t size, laserline::command_ack_t* out, const Limits& limits,
            std::string* problem);

// The type fingerprint in front of an encoded message (0 when shorter than one).
std::int64_t message_hash(const void* data, std::size_t size);

// The pixels of a decoded image_t as an owning cv::Mat: 8-bit grey or 16-bit (host order) for
// uncompressed and zlib frames, what the codec holds for PNG/JPEG (`imread_flags`, e.g.
// cv::IMREAD_GRAYSCALE or cv::IMREAD_UNCHANGED). Width and height must lie within `limits`; the
// row stride and size must fit the data; zlib output is bounded to the frame's bytes; a PNG's or
// JPEG's own dimensions are read from its header and must be the message's before it is decoded.
// False with a one-line reason in *problem otherwise; no exception escapes.
bool unpack_image(const laserline::image_t& message, const Limits& limits, int imread_flags,
                  cv::Mat* out, std::string* problem);

// The width and height a PNG or JPEG stream declares in its header; false when none is found.
bool compressed_image_size(const std::uint8_t* data, std::size_t size, int* width, int* height);

// Reports bad input at a limited rate: the first kFirst problems of each kind (e.g. a channel and
// what went wrong) one line each, then at most one line per kind every kEvery with how many more
// there were, so that a flood of bad messages cannot flood the log. One thread.
class ProblemLog {
 public:
  static constexpr int kFirst = 3;
  static constexpr std::chrono::seconds kEvery{10};

  explicit ProblemLog(std::string prefix) : prefix_(std::move(prefix)) {}
  // Counts one problem of `kind` and prints `line` (prefixed) if the rate allows.
  void report(const std::string& kind, const std::string& line);
  std::int64_t total() const { return total_; }

 private:
  struct Kind {
    std::int64_t count = 0;
    std::int64_t unreported = 0;
    std::chrono::steady_clock::time_point last_line{};
  };
  std::string prefix_;
  std::map<std::string, Kind> kinds_;
  std::int64_t total_ = 0;
};

}  // namespace laserline::messages
