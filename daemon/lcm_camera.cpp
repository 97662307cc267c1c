#include "daemon/lcm_camera.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hal/calibration.hpp"
#include "hal/clock.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::daemon {

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::size_t kMaxReportedChannels = 32;
constexpr const char* kRecordForReplay =
    "frames that replay are recorded with lcm.image_every_n: 1, lcm.image_downscale: 1, no "
    "lcm.image_roi and lcm.image_compression none, zlib or png (config/record.yaml)";

const char* compression_name(std::int8_t compression) {
  switch (compression) {
    case laserline::image_t::COMPRESSION_NONE:
      return "none";
    case laserline::image_t::COMPRESSION_ZLIB:
      return "zlib";
    case laserline::image_t::COMPRESSION_PNG:
      return "png";
    case laserline::image_t::COMPRESSION_JPEG:
      return "jpeg";
    default:
      return "unknown";
  }
}

// "160x128, image_downscale 2, compression jpeg" (and the region's corner when cropped).
std::string recorded_frame(const laserline::image_t& m) {
  std::string s = std::to_string(m.width) + "x" + std::to_string(m.height) + ", image_downscale " +
                  std::to_string(m.downscale);
  if (m.roi_x != 0 || m.roi_y != 0) {
    s += ", image_roi at " + std::to_string(m.roi_x) + "," + std::to_string(m.roi_y);
  }
  return s + ", compression " + compression_name(m.compression);
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
  // A frame is at most the calibrated size in 16 bit; PNG may add a little to that.
  limits_.max_width = options_.width;
  limits_.max_height = options_.height;
  limits_.max_image_bytes =
      2 * static_cast<std::int64_t>(options_.width) * options_.height + (64 << 10);
}

LcmCamera::~LcmCamera() = default;

bool LcmCamera::open(std::string* error) {
  if (offline_) {
    if (log_.open(path_, error)) return true;
    *error = "camera.lcm.url: " + *error;
    return false;
  }
  lcm_ = std::make_unique<lcm::LCM>(options_.url);
  if (!lcm_->good()) {
    *error = "camera.lcm.url: cannot open LCM '" + options_.url + "'";
    return false;
  }
  lcm_->subscribeFunction(options_.channel, &LcmCamera::on_live_event, this);
  lcm_->subscribeFunction(options_.calibration_channel, &LcmCamera::on_live_calibration, this);
  return true;
}

void LcmCamera::stop() {
  stopping_.store(true);
}

LcmCamera::Counts LcmCamera::counts() const {
  const std::int64_t bad_messages = bad_messages_.load(), bad_frames = bad_frames_.load();
  return {frames_.load(),       bad_messages + bad_frames, bad_messages,         bad_frames,
          other_events_.load(), damaged_regions_.load(),   damaged_bytes_.load()};
}

hal::CameraHealth LcmCamera::health() const {
  hal::CameraHealth h;
  h.bad_messages = bad_messages_.load(std::memory_order_relaxed);
  h.bad_frames = bad_frames_.load(std::memory_order_relaxed);
  return h;
}

hal::GrabStatus LcmCamera::grab(std::span<std::uint8_t> dst, hal::FrameInfo& info,
                                std::chrono::milliseconds timeout) {
  if (stopping_.load()) return hal::GrabStatus::kStopped;
  return offline_ ? grab_offline(dst, info) : grab_live(dst, info, timeout);
}

hal::GrabStatus LcmCamera::grab_offline(std::span<std::uint8_t> dst, hal::FrameInfo& info) {
  if (ended_) return hal::GrabStatus::kStopped;
  while (!stopping_.load(std::memory_order_relaxed)) {
    messages::LcmLogReader::Damage damage;
    const bool more = log_.next(&event_, &damage);
    if (damage.bytes > 0) {
      damaged_regions_.fetch_add(1);
      damaged_bytes_.fetch_add(damage.bytes);
      const std::string first = std::to_string(damage.offset);
      const std::string bytes = std::to_string(damage.bytes);
      // Through the problem log: a log damaged all over gives a few lines, not one per region.
      if (more) {
        problems_.report(
            "log damage",
            path_ + ": bytes " + first + ".." + std::to_string(damage.offset + damage.bytes - 1) +
                " are damaged (" + bytes + " bytes, " + std::to_string(damage.records) +
                " records, not LCM log events); skipped, replay resumes at event " +
                std::to_string(event_.number) + " at byte " + std::to_string(event_.offset));
      } else {
        problems_.report("log end", path_ +
                                        ": the log ends inside an event or in damage: the last " +
                                        bytes + " bytes (from byte " + first +
                                        ") are not a complete LCM log event (recording cut "
                                        "short?); ignored");
      }
    }
    if (!more) break;
    const std::string where = path_ + ": event " + std::to_string(event_.number) + " at byte " +
                              std::to_string(event_.offset);
    if (event_.channel == options_.calibration_channel) {
      if (check_calibration(event_.data.data(), static_cast<int>(event_.data.size()), where)) {
        continue;
      }
      ended_ = true;
      return hal::GrabStatus::kStopped;
    }
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
    if (refused_.load()) return hal::GrabStatus::kStopped;
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

void LcmCamera::on_live_calibration(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                                    LcmCamera* self) {
  if (self->refused_.load()) return;
  self->check_calibration(rbuf->data, static_cast<int>(rbuf->data_size),
                          self->options_.url + " " + channel);
}

bool LcmCamera::check_calibration(const void* data, int size, const std::string& where) {
  laserline::calibration_t recorded;
  std::string problem;
  if (!messages::decode(data, static_cast<std::size_t>(size), &recorded, limits_, &problem)) {
    bad_messages_.fetch_add(1);
    problems_.report(options_.calibration_channel + " bad message",
                     where + ": not a valid laserline.calibration_t: " + problem + "; ignored");
    return true;
  }
  const auto id = static_cast<std::uint64_t>(recorded.calibration_id);
  if (id == options_.calibration_id) return true;
  std::fprintf(stderr,
               "laserlined: replay %s: recorded with calibration %s, but the configuration's is "
               "%s: the replay's 3-D points would be wrong; configure the calibration it was "
               "recorded with (laserline-extract uses a log's own); replay refused\n",
               where.c_str(), hal::calibration_id_text(id).c_str(),
               hal::calibration_id_text(options_.calibration_id).c_str());
  refused_.store(true);
  return false;
}

bool LcmCamera::skip_frame(bool bad_message, const std::string& kind, const std::string& where,
                           const std::string& problem) {
  (bad_message ? bad_messages_ : bad_frames_).fetch_add(1);
  problems_.report(kind, where + ": " + problem + "; frame skipped");
  return false;
}

bool LcmCamera::take_frame(const void* data, int size, const std::string& where,
                           std::span<std::uint8_t> dst, hal::FrameInfo& info) {
  std::string problem;
  const std::string& channel = options_.channel;
  if (size < 0 ||
      !messages::decode(data, static_cast<std::size_t>(size), &image_, limits_, &problem)) {
    return skip_frame(true, channel + " bad message", where,
                      "not a valid laserline.image_t: " + problem);
  }
  if (image_.pixelformat != laserline::image_t::PIXEL_FORMAT_GRAY) {
    return skip_frame(false, channel + " pixel format", where,
                      "pixel format " + std::to_string(image_.pixelformat) +
                          " is not 8-bit grey (PIXEL_FORMAT_GRAY)");
  }
  if (image_.width != format_.width || image_.height != format_.height || image_.downscale > 1 ||
      image_.roi_x != 0 || image_.roi_y != 0) {
    const std::string recorded = recorded_frame(image_);
    if (unfit_frame_.empty()) unfit_frame_ = recorded;
    unfit_frames_.fetch_add(1);
    return skip_frame(false, channel + " frame size", where,
                      "the recorded frame (" + recorded + ") does not fit the calibration's " +
                          std::to_string(format_.width) + "x" + std::to_string(format_.height) +
                          " frame");
  }
  if (image_.compression == laserline::image_t::COMPRESSION_JPEG && !jpeg_reported_) {
    jpeg_reported_ = true;
    std::fprintf(stderr,
                 "laserlined: replay %s: frames are JPEG (lossy): the profiles differ from the "
                 "original run's; %s\n",
                 where.c_str(), kRecordForReplay);
  }
  if (!messages::unpack_image(image_, limits_, cv::IMREAD_GRAYSCALE, &pixels_, &problem)) {
    return skip_frame(false, channel + " pixels", where, problem);
  }
  if (pixels_.type() != CV_8UC1 || pixels_.cols != format_.width ||
      pixels_.rows != format_.height) {
    return skip_frame(false, channel + " pixels", where, "pixels are not an 8-bit grey frame");
  }
  const auto row_bytes = static_cast<std::size_t>(format_.width);
  for (int row = 0; row < format_.height; ++row) {
    std::memcpy(dst.data() + static_cast<std::size_t>(row) * format_.stride, pixels_.ptr(row),
                row_bytes);
  }
  // The recorded exposure becomes the frame's exposure, so the replay's profiles carry the
  // original utime; on this host the frame is exposed (as far as latency goes) when it arrives.
  const std::int64_t now = hal::monotonic_ns();
  if (frames_.load(std::memory_order_relaxed) > 0 && image_.sequence > last_sequence_ + 1) {
    missing_frames_ += image_.sequence - last_sequence_ - 1;
  }
  last_sequence_ = image_.sequence;
  info.sequence = static_cast<std::uint64_t>(image_.sequence);
  info.camera_ns = image_.camera_timestamp_ns;
  info.laser_on = image_.laser_on;
  info.exposure_us = image_.exposure_us;
  info.gain_db = image_.gain_db;
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
  // Why a replay gave nothing (or lost frames for their size), in one line with the remedy.
  const std::string calibrated =
      std::to_string(format_.width) + "x" + std::to_string(format_.height);
  if (!unfit_frame_.empty()) {
    std::fprintf(stderr,
                 "laserlined: replay %s: %lld recorded frames do not fit the calibration's %s "
                 "frame (recorded: %s); %s\n",
                 path_.c_str(), static_cast<long long>(unfit_frames_.load()), calibrated.c_str(),
                 unfit_frame_.c_str(), kRecordForReplay);
  } else if (missing_frames_ > 0) {
    std::fprintf(stderr,
                 "laserlined: replay %s: %lld frames are missing between the replayed ones (gaps "
                 "in their sequence numbers: recorded with lcm.image_every_n above 1, or raw "
                 "frames dropped); %s\n",
                 path_.c_str(), static_cast<long long>(missing_frames_), kRecordForReplay);
  } else if (c.frames == 0 && c.frames_skipped == 0) {
    std::fprintf(stderr,
                 "laserlined: replay %s: the log holds no raw frame on '%s' (recorded with "
                 "lcm.image_every_n: 0?); %s\n",
                 path_.c_str(), options_.channel.c_str(), kRecordForReplay);
  }
}

namespace {

// The `lcm` backend: options under `camera.lcm`: url, channel, calibration_channel.
std::unique_ptr<hal::Camera> create_lcm_camera(const hal::CameraRequest& request) {
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
  o.calibration_channel = lcm.string("calibration_channel", o.calibration_channel);
  if (o.calibration_channel.empty()) lcm.fail("calibration_channel", "must not be empty");
  o.calibration_id = hal::calibration_id(*request.calibration);
  lcm.finish();
  o.width = request.calibration->camera.width;
  o.height = request.calibration->camera.height;
  return std::make_unique<LcmCamera>(std::move(o));
}

const hal::CameraBackendRegistration kLcm{"lcm", create_lcm_camera};

}  // namespace

}  // namespace laserline::daemon
