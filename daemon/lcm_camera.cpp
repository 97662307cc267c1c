#include "daemon/lcm_camera.hpp"

#include <sys/types.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hal/clock.hpp"
#include "hal/registry.hpp"

namespace laserline::daemon {

namespace {

constexpr std::int64_t kMs = 1'000'000;
// Magic, event number, timestamp, channel length, data length: the LCM log event header.
constexpr std::int64_t kEventHeaderBytes = 4 + 8 + 8 + 4 + 4;
constexpr std::size_t kMaxReportedChannels = 32;
constexpr std::uint32_t kEventMarker = 0xEDA1DA01;
// Limits a sane event stays within; a header beyond them is damage, not a huge allocation.
constexpr std::int32_t kMaxChannelBytes = 256;
constexpr std::int32_t kMaxEventBytes = 256 << 20;

std::uint64_t big_endian(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i)
    v = (v << 8) | p[i];
  return v;
}

std::string compression_name(std::int8_t c) {
  switch (c) {
    case laserline::image_t::COMPRESSION_NONE:
      return "none";
    case laserline::image_t::COMPRESSION_PNG:
      return "png";
    case laserline::image_t::COMPRESSION_JPEG:
      return "jpeg";
    case laserline::image_t::COMPRESSION_ZLIB:
      return "zlib";
  }
  return std::to_string(c);
}

}  // namespace

LcmCamera::LcmCamera(Options options) : options_(std::move(options)) {
  format_.width = options_.width;
  format_.height = options_.height;
  format_.stride = options_.width;
  format_.pixel_format = hal::PixelFormat::kMono8;
  offline_ = options_.url.rfind("file://", 0) == 0;
  if (offline_) {
    path_ = options_.url.substr(7);
    path_ = path_.substr(0, path_.find('?'));
  }
  reported_channels_.reserve(kMaxReportedChannels);
}

LcmCamera::~LcmCamera() = default;

bool LcmCamera::open(std::string* error) {
  if (offline_) return log_.open(path_, error);
  lcm_ = std::make_unique<lcm::LCM>(options_.url);
  if (!lcm_->good()) {
    *error = "camera.lcm.url: cannot open LCM '" + options_.url + "'";
    return false;
  }
  lcm_->subscribeFunction(options_.channel, &LcmCamera::on_live_event, this);
  return true;
}

void LcmCamera::stop() {
  stopping_.store(true);
}

LcmCamera::Counts LcmCamera::counts() const {
  return {frames_.load(), frames_skipped_.load(), other_events_.load(), damaged_regions_.load(),
          damaged_bytes_.load()};
}

hal::GrabStatus LcmCamera::grab(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                                std::chrono::milliseconds timeout) {
  if (stopping_.load()) return hal::GrabStatus::kStopped;
  return offline_ ? grab_offline(dst, info) : grab_live(dst, info, timeout);
}

hal::GrabStatus LcmCamera::grab_offline(std::span<std::uint8_t> dst, hal::FrameInfo& info) {
  if (ended_) return hal::GrabStatus::kStopped;
  while (!stopping_.load(std::memory_order_relaxed)) {
    LcmLogReader::Damage damage;
    const bool more = log_.next(&event_, &damage);
    if (damage.bytes > 0) {
      damaged_regions_.fetch_add(1);
      damaged_bytes_.fetch_add(damage.bytes);
      const long long first = damage.offset, last = damage.offset + damage.bytes - 1;
      if (more) {
        std::fprintf(stderr,
                     "laserlined: replay %s: bytes %lld..%lld are damaged (%lld bytes, not an LCM "
                     "log event); skipped, replay resumes at event %lld at byte %lld\n",
                     path_.c_str(), first, last, static_cast<long long>(damage.bytes),
                     static_cast<long long>(event_.number), static_cast<long long>(event_.offset));
      } else {
        std::fprintf(stderr,
                     "laserlined: replay %s: damaged tail: the last %lld bytes (from byte %lld) "
                     "are not a complete LCM log event; ignored\n",
                     path_.c_str(), static_cast<long long>(damage.bytes), first);
      }
    }
    if (!more) break;
    const std::string where = path_ + ": event " + std::to_string(event_.number) + " at byte " +
                              std::to_string(event_.offset);
    if (event_.channel != options_.channel) {
      note_channel(event_.channel, where);
      continue;
    }
    if (take_frame(event_.data.data(), static_cast<int>(event_.data.size()), where, dst, info)) {
      return hal::GrabStatus::kOk;
    }
  }
  if (stopping_.load()) return hal::GrabStatus::kStopped;
  ended_ = true;
  report_end();
  return hal::GrabStatus::kStopped;
}

hal::GrabStatus LcmCamera::grab_live(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                                     std::chrono::milliseconds timeout) {
  live_dst_ = dst;
  live_info_ = &info;
  live_got_frame_ = false;
  const std::int64_t deadline = hal::monotonic_ns() + timeout.count() * kMs;
  while (!stopping_.load(std::memory_order_relaxed)) {
    const std::int64_t remaining = deadline - hal::monotonic_ns();
    if (remaining <= 0) return hal::GrabStatus::kTimeout;
    // Short slices, so that stop() is seen within 100 ms.
    const int slice_ms = static_cast<int>(std::clamp<std::int64_t>(remaining / kMs, 1, 100));
    if (lcm_->handleTimeout(slice_ms) < 0) return hal::GrabStatus::kError;
    if (live_got_frame_) return hal::GrabStatus::kOk;
  }
  return hal::GrabStatus::kStopped;
}

void LcmCamera::on_live_event(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                              LcmCamera* self) {
  const std::string where = self->options_.url + " " + channel;
  if (self->take_frame(rbuf->data, static_cast<int>(rbuf->data_size), where, self->live_dst_,
                       *self->live_info_)) {
    self->live_got_frame_ = true;
  }
}

bool LcmCamera::take_frame(const void* data, int size, const std::string& where,
                           std::span<std::uint8_t> dst, hal::FrameInfo& info) {
  auto skip = [&](const std::string& problem) {
    frames_skipped_.fetch_add(1);
    std::fprintf(stderr, "laserlined: replay %s: %s; frame skipped\n", where.c_str(),
                 problem.c_str());
    return false;
  };
  if (image_.decode(data, 0, size) < 0) {
    return skip("not a laserline.image_t (" + std::to_string(size) +
                " bytes that do not decode as one)");
  }
  if (image_.pixelformat != laserline::image_t::PIXEL_FORMAT_GRAY) {
    return skip("pixel format " + std::to_string(image_.pixelformat) +
                " is not 8-bit grey (PIXEL_FORMAT_GRAY)");
  }
  if (image_.width != format_.width || image_.height != format_.height) {
    return skip("frame " + std::to_string(image_.width) + "x" + std::to_string(image_.height) +
                " differs from the calibrated camera's " + std::to_string(format_.width) + "x" +
                std::to_string(format_.height));
  }
  if (image_.downscale > 1 || image_.roi_x != 0 || image_.roi_y != 0) {
    return skip(
        "a downscaled or cropped raw frame cannot be replayed (record with "
        "lcm.image_downscale 1 and no lcm.image_roi)");
  }
  const std::size_t row_bytes = static_cast<std::size_t>(format_.width);
  const std::uint8_t* pixels = image_.data.data();
  std::size_t stride = static_cast<std::size_t>(image_.row_stride);
  std::size_t available = image_.data.size();
  switch (image_.compression) {
    case laserline::image_t::COMPRESSION_NONE:
      break;
    case laserline::image_t::COMPRESSION_ZLIB: {
      unpacked_.resize(format_.bytes());
      uLongf got = static_cast<uLongf>(unpacked_.size());
      const int z = uncompress(unpacked_.data(), &got, image_.data.data(),
                               static_cast<uLong>(image_.data.size()));
      if (z != Z_OK || got != unpacked_.size()) {
        return skip("zlib data do not unpack to a " + std::to_string(format_.width) + "x" +
                    std::to_string(format_.height) + " frame (" + zError(z) + ")");
      }
      pixels = unpacked_.data();
      stride = row_bytes;
      available = got;
      break;
    }
    case laserline::image_t::COMPRESSION_PNG:
    case laserline::image_t::COMPRESSION_JPEG: {
      const cv::Mat decoded = cv::imdecode(
          cv::Mat(1, static_cast<int>(image_.data.size()), CV_8UC1, image_.data.data()),
          cv::IMREAD_GRAYSCALE);
      if (decoded.empty() || decoded.cols != format_.width || decoded.rows != format_.height) {
        return skip(compression_name(image_.compression) + " data do not decode to a " +
                    std::to_string(format_.width) + "x" + std::to_string(format_.height) +
                    " frame");
      }
      unpacked_.resize(format_.bytes());
      for (int row = 0; row < format_.height; ++row)
        std::memcpy(unpacked_.data() + row * row_bytes, decoded.ptr(row), row_bytes);
      pixels = unpacked_.data();
      stride = row_bytes;
      available = unpacked_.size();
      break;
    }
    default:
      return skip("unknown compression " + std::to_string(image_.compression));
  }
  if (stride < row_bytes || available < stride * (format_.height - 1) + row_bytes) {
    return skip("row stride " + std::to_string(stride) + " and " + std::to_string(available) +
                " bytes do not hold a " + std::to_string(format_.width) + "x" +
                std::to_string(format_.height) + " frame");
  }
  for (int row = 0; row < format_.height; ++row) {
    std::memcpy(dst.data() + static_cast<std::size_t>(row) * format_.stride,
                pixels + static_cast<std::size_t>(row) * stride, row_bytes);
  }
  // The recorded exposure becomes the frame's exposure, so the replay's profiles carry the
  // original utime; on this host the frame is exposed (as far as latency goes) when it arrives.
  const std::int64_t now = hal::monotonic_ns();
  info.sequence = static_cast<std::uint64_t>(image_.sequence);
  info.camera_ns = image_.camera_timestamp_ns;
  info.laser_on = image_.laser_on;
  info.arrival_mono_ns = now;
  info.exposure_mono_ns = now;
  info.arrival_wall_ns = image_.utime * 1000;
  frames_.fetch_add(1);
  return true;
}

void LcmCamera::note_channel(const std::string& channel, const std::string& where) {
  other_events_.fetch_add(1);
  if (std::find(reported_channels_.begin(), reported_channels_.end(), channel) !=
          reported_channels_.end() ||
      reported_channels_.size() >= kMaxReportedChannels) {
    return;
  }
  reported_channels_.push_back(channel);
  std::fprintf(stderr,
               "laserlined: replay %s: events on channel '%s' are not replayed (only raw frames "
               "on '%s' are)\n",
               where.c_str(), channel.c_str(), options_.channel.c_str());
}

void LcmCamera::report_end() {
  const Counts c = counts();
  std::fprintf(stderr,
               "laserlined: replay %s: end of log: %lld frames replayed, %lld skipped, %lld events "
               "on other channels, %lld damaged regions (%lld bytes)\n",
               path_.c_str(), static_cast<long long>(c.frames),
               static_cast<long long>(c.frames_skipped), static_cast<long long>(c.other_events),
               static_cast<long long>(c.damaged_regions), static_cast<long long>(c.damaged_bytes));
}

LcmLogReader::~LcmLogReader() {
  if (file_ != nullptr) std::fclose(file_);
}

bool LcmLogReader::open(const std::string& path, std::string* error) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) {
    *error = "camera.lcm.url: cannot read log '" + path + "': " + ec.message();
    return false;
  }
  file_ = std::fopen(path.c_str(), "rb");
  if (file_ == nullptr) {
    *error = "camera.lcm.url: cannot open log '" + path + "': " + std::strerror(errno);
    return false;
  }
  size_ = static_cast<std::int64_t>(size);
  position_ = 0;
  return true;
}

bool LcmLogReader::read_at(std::int64_t offset, Event* event) {
  std::uint8_t header[kEventHeaderBytes];
  if (fseeko(file_, offset, SEEK_SET) != 0 ||
      std::fread(header, 1, sizeof header, file_) != sizeof header) {
    return false;
  }
  if (big_endian(header, 4) != kEventMarker) return false;
  const auto channel_bytes = static_cast<std::int32_t>(big_endian(header + 20, 4));
  const auto data_bytes = static_cast<std::int32_t>(big_endian(header + 24, 4));
  if (channel_bytes <= 0 || channel_bytes > kMaxChannelBytes || data_bytes < 0 ||
      data_bytes > kMaxEventBytes ||
      offset + kEventHeaderBytes + channel_bytes + data_bytes > size_) {
    return false;
  }
  event->channel.resize(static_cast<std::size_t>(channel_bytes));
  event->data.resize(static_cast<std::size_t>(data_bytes));
  if (std::fread(event->channel.data(), 1, event->channel.size(), file_) != event->channel.size() ||
      std::fread(event->data.data(), 1, event->data.size(), file_) != event->data.size()) {
    return false;
  }
  event->offset = offset;
  event->number = static_cast<std::int64_t>(big_endian(header + 4, 8));
  position_ = offset + kEventHeaderBytes + channel_bytes + data_bytes;
  return true;
}

std::int64_t LcmLogReader::find_marker(std::int64_t from) {
  constexpr std::size_t kChunk = 64 * 1024;
  scan_.resize(kChunk + 3);
  for (std::int64_t base = from; base < size_; base += kChunk) {
    if (fseeko(file_, base, SEEK_SET) != 0) return size_;
    // 3 bytes of overlap so that a marker across two chunks is found.
    const std::size_t got = std::fread(scan_.data(), 1, scan_.size(), file_);
    for (std::size_t i = 0; i + 4 <= got; ++i) {
      if (big_endian(scan_.data() + i, 4) == kEventMarker) {
        return base + static_cast<std::int64_t>(i);
      }
    }
  }
  return size_;
}

bool LcmLogReader::next(Event* event, Damage* damage) {
  *damage = {};
  const std::int64_t start = position_;
  // At an event boundary the next event starts here; after damage, at the next marker that
  // begins a whole event.
  for (std::int64_t at = start; at < size_; at = find_marker(at + 1)) {
    if (read_at(at, event)) {
      if (at > start) *damage = {start, at - start};
      return true;
    }
  }
  if (size_ > start) *damage = {start, size_ - start};
  position_ = size_;
  return false;
}

void register_lcm_camera() {
  hal::register_camera_backend("lcm", [](const hal::CameraRequest& request) {
    hal::YamlMap lcm = request.options->map("lcm");
    LcmCamera::Options o;
    o.url = lcm.string("url", "");
    if (o.url.empty()) {
      lcm.fail("url", "required: file:///path/to/dive.lcmlog (offline) or an LCM URL (live)");
    }
    if (o.url.rfind("file://", 0) == 0 && o.url.size() == 7) {
      lcm.fail("url", "file:// needs the path of a log file");
    }
    o.channel = lcm.string("channel", o.channel);
    if (o.channel.empty()) lcm.fail("channel", "must not be empty");
    lcm.finish();
    o.width = request.calibration->camera.width;
    o.height = request.calibration->camera.height;
    return std::make_unique<LcmCamera>(std::move(o));
  });
}

}  // namespace laserline::daemon
