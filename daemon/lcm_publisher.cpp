#include "daemon/lcm_publisher.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "hal/clock.hpp"

namespace laserline::daemon {

namespace {

// LCM's lines on stderr, joined into one; "connecting..." progress lines left out.
std::string one_line(const std::string& text) {
  std::string joined;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(start, end - start);
    start = end + 1;
    if (line.empty() || line.ends_with("...")) continue;
    joined += (joined.empty() ? "" : "; ") + line;
  }
  return joined;
}

}  // namespace

std::unique_ptr<lcm::LCM> open_lcm(const std::string& url, std::string* error) {
  // stderr goes into a pipe while LCM starts. Non-blocking: a longer complaint than the pipe
  // holds is cut short instead of blocking the write.
  int pipe_fds[2] = {-1, -1};
  const bool capture = pipe2(pipe_fds, O_CLOEXEC | O_NONBLOCK) == 0;
  int saved_stderr = -1;
  if (capture) {
    std::fflush(stderr);
    saved_stderr = dup(STDERR_FILENO);
    dup2(pipe_fds[1], STDERR_FILENO);
  }
  auto lcm = std::make_unique<lcm::LCM>(url);
  const bool tcpq_unconnected = lcm->good() && url.starts_with("tcpq://") && lcm->getFileno() < 0;
  std::string said;
  if (capture) {
    std::fflush(stderr);
    dup2(saved_stderr, STDERR_FILENO);
    close(saved_stderr);
    close(pipe_fds[1]);
    char buffer[4096];
    ssize_t n;
    while ((n = read(pipe_fds[0], buffer, sizeof buffer)) > 0)
      said.append(buffer, static_cast<std::size_t>(n));
    close(pipe_fds[0]);
  }
  if (lcm->good() && !tcpq_unconnected) {
    if (!said.empty()) std::fputs(said.c_str(), stderr);
    return lcm;
  }
  if (error != nullptr) {
    const std::string why = one_line(said);
    *error = "cannot open '" + url + "'" + (tcpq_unconnected ? ": no tcpq hub answered" : "") +
             (why.empty() ? "" : ": " + why);
  }
  return nullptr;
}

std::int64_t frame_utime(const hal::FrameInfo& info) {
  return info.exposure_wall_ns() / 1000;
}

std::int64_t process_instance_id() {
  static const std::int64_t id = [] {
    std::random_device random;
    std::uint64_t v = 0;
    while (v == 0)
      v = (std::uint64_t{random()} << 32) | random();
    return static_cast<std::int64_t>(v);
  }();
  return id;
}

LcmPublisher::LcmPublisher(lcm::LCM& lcm, lcm::LCM* image_lcm, PublisherChannels channels,
                           const std::string& detector, std::size_t max_points,
                           const hal::FrameFormat& format, const hal::Calibration& calibration)
    : lcm_(lcm),
      image_lcm_(image_lcm != nullptr ? *image_lcm : lcm),
      channels_(std::move(channels)) {
  profile_.detector = detector;
  profile_.points.resize(max_points);
  profile_.num_points = static_cast<std::int32_t>(max_points);
  image_.data.resize(format.bytes());
  image_.size = static_cast<std::int32_t>(format.bytes());
  status_.detector = detector;
  status_.camera_state = "starting";
  status_.instance_id = process_instance_id();
  profile_.instance_id = status_.instance_id;
  calibration_ = calibration_message(calibration, status_.instance_id);
  profile_.calibration_id = calibration_.calibration_id;
  const std::size_t largest =
      std::max({static_cast<std::size_t>(profile_.getEncodedSize()), std::size_t{4096}});
  // Room for longer status strings than the ones measured here.
  buffer_.resize(largest + 1024);
  // A compressed frame may come out a little larger than the raw one.
  image_buffer_.resize(static_cast<std::size_t>(image_.getEncodedSize()) + format.bytes() / 8 +
                       4096);
  image_.data.reserve(format.bytes() + format.bytes() / 8 + 4096);
  profile_.points.clear();
  profile_.num_points = 0;
}

template <typename Message>
bool LcmPublisher::publish(lcm::LCM& lcm, const std::string& channel, const Message& message,
                           std::vector<std::uint8_t>& buffer) {
  const int size = message.getEncodedSize();
  if (size < 0 || static_cast<std::size_t>(size) > buffer.size()) return false;
  if (message.encode(buffer.data(), 0, size) != size) return false;
  return lcm.publish(channel, buffer.data(), static_cast<unsigned>(size)) == 0;
}

// profile_t.search_axis carries pipeline::SearchAxis as is.
static_assert(static_cast<int>(pipeline::SearchAxis::kColumns) ==
              laserline::profile_t::SEARCH_COLUMNS);
static_assert(static_cast<int>(pipeline::SearchAxis::kRows) == laserline::profile_t::SEARCH_ROWS);
static_assert(static_cast<int>(pipeline::SearchAxis::kOblique) ==
              laserline::profile_t::SEARCH_OBLIQUE);

bool LcmPublisher::publish_profile(const ProfileSlot& slot) {
  profile_.utime = frame_utime(slot.info);
  profile_.sequence = static_cast<std::int64_t>(slot.info.sequence);
  profile_.camera_timestamp_ns = slot.info.camera_ns;
  profile_.laser_on = slot.info.laser_on;
  profile_.exposure_us = slot.info.exposure_us;
  profile_.gain_db = slot.info.gain_db;
  profile_.width = slot.width;
  profile_.height = slot.height;
  profile_.background_sequence = slot.profile.background_sequence();
  profile_.background_laser_off = slot.profile.background_laser_off();
  const pipeline::SearchAxes& axes = slot.profile.axes();
  profile_.search_axis = static_cast<std::int8_t>(axes.axis);
  std::copy(axes.origin.begin(), axes.origin.end(), profile_.search_origin);
  std::copy(axes.line_step.begin(), axes.line_step.end(), profile_.search_line_step);
  std::copy(axes.along.begin(), axes.along.end(), profile_.search_along);
  const auto& points = slot.profile.points();
  profile_.points.resize(points.size());  // within the capacity reserved at construction
  std::size_t n = 0;
  for (const pipeline::ProfilePoint& p : points) {
    if (!p.valid && !channels_.all_points) continue;
    laserline::point_t& out = profile_.points[n++];
    out.u = static_cast<std::int16_t>(p.u);
    out.v = p.v;
    out.snr_db = p.snr_db;
    out.segment = p.segment;
    out.valid = p.valid;
    std::copy(p.xyz.begin(), p.xyz.end(), out.xyz);
  }
  profile_.points.resize(n);
  profile_.num_points = static_cast<std::int32_t>(n);
  return publish(lcm_, channels_.profile, profile_, buffer_);
}

bool LcmPublisher::publish_image(const ImageSlot& slot, RawFrameEncoder& encoder) {
  image_.utime = frame_utime(slot.info);
  image_.sequence = static_cast<std::int64_t>(slot.info.sequence);
  image_.camera_timestamp_ns = slot.info.camera_ns;
  image_.laser_on = slot.info.laser_on;
  image_.exposure_us = slot.info.exposure_us;
  image_.gain_db = slot.info.gain_db;
  if (!encoder.encode(slot, &image_)) return false;
  return publish(image_lcm_, channels_.image, image_, image_buffer_);
}

bool LcmPublisher::publish_status() {
  return publish(lcm_, channels_.status, status_, buffer_);
}

bool LcmPublisher::publish_calibration() {
  calibration_.utime = hal::wall_ns() / 1000;
  return publish(lcm_, channels_.calibration, calibration_, buffer_);
}

}  // namespace laserline::daemon
