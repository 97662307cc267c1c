// laserline-view: subscribes to a laserline daemon over LCM and serves a live view of it to a
// browser: the latest raw frame with its points, the profile, the points of the last seconds in
// 3-D and the daemon's status, pushed as server-sent events.
//
// Threads: the LCM thread decodes each message (checked) and stores the latest under one mutex;
// the HTTP threads take copies. Malformed messages are counted, shown, and skipped.
//
// Controls (--allow-control, with a --token the page must give): the page posts a setting to
// /command; the view checks the token, sends a laserline.command_t carrying it to the daemon and
// answers with the daemon's command_ack_t.
#include <httplib.h>
#include <netdb.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>
#include <laserline/command_ack_t.hpp>
#include <laserline/command_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "lcmtypes/checked_decode.hpp"
#include "tools/cli.hpp"
#include "tools/view_assets.hpp"

namespace {

constexpr const char* kUsage =
    "usage: laserline-view [--listen ADDR:PORT] [--url URL] [--profile-channel C]\n"
    "                      [--image-channel C] [--status-channel C] [--history S]\n"
    "                      [--frame-rate HZ] [--profile-rate HZ]\n"
    "                      [--allow-control --token TEXT [--command-channel C]]\n"
    "  --listen ADDR:PORT  where the page is served (default 127.0.0.1:8090, this computer only;\n"
    "                      0.0.0.0:8090 for every network; port 0: any free port)\n"
    "  --url URL           LCM URL (default: LCM_DEFAULT_URL or udpm://239.255.76.67:7667?ttl=0)\n"
    "  --history S         seconds of points in the 3-D view (default 5)\n"
    "  --frame-rate HZ     raw frames sent to each browser at most this often (default 5)\n"
    "  --profile-rate HZ   profiles sent to each browser at most this often (default 10)\n"
    "  --allow-control     controls on the page: exposure, gain, the laser's mode; each use\n"
    "                      needs the --token typed into the page (the laser is a Class 3B hazard)\n"
    "  --token TEXT        that token, also sent with each command: the daemon's\n"
    "                      lcm.command_token when it has one\n"
    "  --command-channel C the daemon's lcm.command_channel (default LASERLINE_COMMAND; answers\n"
    "                      on C_ACK)\n"
    "Open the address it prints in a browser. Everything the page needs is in this program.\n";

// How long /command waits for the daemon's answer.
constexpr std::chrono::seconds kCommandTimeout{3};

using Clock = std::chrono::steady_clock;

// Live streams open at once; the HTTP thread pool keeps threads for the page's files besides.
constexpr int kMaxStreams = 8;
constexpr std::size_t kHttpThreads = kMaxStreams + 4;
// Points of one profile kept for the 3-D view (every n-th): enough for the shape, small to send.
constexpr std::size_t kCloudPointsPerProfile = 160;
constexpr std::size_t kRecentProfiles = 64;  // to pair a raw frame with its profile
constexpr int kJpegQuality = 85;

// --- JSON, written by hand: numbers, strings, arrays of numbers -----------------------------

void append_string(std::string& out, const std::string& text) {
  out += '"';
  for (const char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\u%04x", static_cast<unsigned>(c));
      out += escaped;
    } else {
      out += c;
    }
  }
  out += '"';
}

void append_number(std::string& out, double value, int decimals = 3) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  char text[48];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  // "1.500" -> "1.5", "2.000" -> "2": smaller events.
  std::string s = text;
  if (s.find('.') != std::string::npos) {
    while (s.back() == '0')
      s.pop_back();
    if (s.back() == '.') s.pop_back();
  }
  if (s == "-0") s = "0";
  out += s;
}

void append_integer(std::string& out, std::int64_t value) {
  out += std::to_string(value);
}

class JsonObject {
 public:
  JsonObject& integer(const char* key, std::int64_t value) {
    this->key(key);
    append_integer(out_, value);
    return *this;
  }
  JsonObject& number(const char* key, double value, int decimals = 3) {
    this->key(key);
    append_number(out_, value, decimals);
    return *this;
  }
  JsonObject& boolean(const char* key, bool value) {
    this->key(key);
    out_ += value ? "true" : "false";
    return *this;
  }
  JsonObject& string(const char* key, const std::string& value) {
    this->key(key);
    append_string(out_, value);
    return *this;
  }
  // Already JSON.
  JsonObject& raw(const char* key, const std::string& json) {
    this->key(key);
    out_ += json;
    return *this;
  }
  std::string str() const { return out_ + "}"; }

 private:
  void key(const char* name) {
    out_ += out_.size() > 1 ? ",\"" : "\"";
    out_ += name;
    out_ += "\":";
  }
  std::string out_ = "{";
};

std::string numbers(const std::vector<float>& values, int decimals) {
  std::string out = "[";
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ',';
    append_number(out, values[i], decimals);
  }
  return out + "]";
}

// --- What arrived -----------------------------------------------------------------------------

struct Channel {
  std::string name;
  std::int64_t received = 0;
  std::int64_t malformed = 0;
  Clock::time_point last{};
};

// Points of one profile for the 3-D view, millimetres in the camera frame.
struct CloudChunk {
  std::int64_t index;
  Clock::time_point received;
  std::int64_t utime;  // exposure: profiles are spaced as exposed, not as they arrived in bursts
  std::vector<float> xyz_mm;
};

struct EncodedFrame {
  std::int64_t sequence = -1;
  std::string jpeg;
};

class LiveState {
 public:
  LiveState(std::string profile_channel, std::string image_channel, std::string status_channel,
            double history_s)
      : history_(
            std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(history_s))) {
    channels_[kProfile].name = std::move(profile_channel);
    channels_[kImage].name = std::move(image_channel);
    channels_[kStatus].name = std::move(status_channel);
  }

  // --- the LCM thread ---
  void on_message(const lcm::ReceiveBuffer* rbuf, const std::string& channel_name) {
    for (int c = 0; c < kChannels; ++c) {
      if (channel_name == channels_[c].name) receive(c, rbuf->data, rbuf->data_size);
    }
  }

  // --- any thread ---
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    changed_.notify_all();
  }

  // One browser's event stream: what it has been sent, and when it may have more.
  class Stream {
   public:
    Stream(LiveState& state, double frame_rate_hz, double profile_rate_hz)
        : state_(state),
          frame_period_(period(frame_rate_hz)),
          profile_period_(period(profile_rate_hz)) {}

    // Waits (at most about a second) for something new that is due and returns it as SSE text;
    // empty when stopping.
    std::string next(bool* stopping);

   private:
    static Clock::duration period(double hz) {
      return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
    }
    LiveState& state_;
    Clock::duration frame_period_, profile_period_;
    std::int64_t status_sent_ = 0, profile_sent_ = 0, frame_sent_ = 0, cloud_sent_ = -1;
    Clock::time_point next_frame_{}, next_profile_{}, next_viewer_{};
    bool started_ = false;
  };

  // The latest raw frame as JPEG (encoded once per frame, whoever asks); nullptr when none
  // arrived or it does not decode (then *problem says why).
  std::shared_ptr<const EncodedFrame> frame_jpeg(std::string* problem);

  std::atomic<int> open_streams_{0};

 private:
  enum { kProfile, kImage, kStatus, kChannels };

  void receive(int c, const void* data, std::size_t size) {
    std::string problem;
    bool ok = false;
    if (c == kProfile) {
      auto p = std::make_shared<laserline::profile_t>();
      ok = laserline::messages::decode(data, size, p.get(), limits_, &problem);
      if (ok) store_profile(std::move(p));
    } else if (c == kImage) {
      auto image = std::make_shared<laserline::image_t>();
      ok = laserline::messages::decode(data, size, image.get(), limits_, &problem);
      if (ok) {
        std::lock_guard<std::mutex> lock(mutex_);
        image_ = std::move(image);
        ++image_count_;
      }
    } else {
      auto s = std::make_shared<laserline::status_t>();
      ok = laserline::messages::decode(data, size, s.get(), limits_, &problem);
      if (ok) {
        std::lock_guard<std::mutex> lock(mutex_);
        status_ = std::move(s);
        ++status_count_;
      }
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      Channel& channel = channels_[c];
      ++channel.received;
      channel.last = Clock::now();
      if (!ok) {
        ++channel.malformed;
        last_problem_ = channel.name + ": " + problem + "; skipped";
      }
    }
    if (!ok) problems_.report(channels_[c].name, channels_[c].name + ": " + problem + "; skipped");
    changed_.notify_all();
  }

  void store_profile(std::shared_ptr<laserline::profile_t> p) {
    CloudChunk chunk{0, Clock::now(), p->utime, {}};
    std::size_t with_xyz = 0;
    for (const auto& pt : p->points) {
      if (pt.valid && std::isfinite(pt.xyz[0]) && std::isfinite(pt.xyz[1]) &&
          std::isfinite(pt.xyz[2])) {
        ++with_xyz;
      }
    }
    const std::size_t step =
        std::max<std::size_t>(1, (with_xyz + kCloudPointsPerProfile - 1) / kCloudPointsPerProfile);
    std::size_t k = 0;
    for (const auto& pt : p->points) {
      if (!pt.valid || !std::isfinite(pt.xyz[0]) || !std::isfinite(pt.xyz[1]) ||
          !std::isfinite(pt.xyz[2])) {
        continue;
      }
      if (k++ % step != 0) continue;
      for (int i = 0; i < 3; ++i)
        chunk.xyz_mm.push_back(pt.xyz[i] * 1000.0f);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    chunk.index = ++profile_count_;
    if (!chunk.xyz_mm.empty()) cloud_.push_back(std::move(chunk));
    while (!cloud_.empty() && cloud_.front().received < Clock::now() - history_)
      cloud_.pop_front();
    recent_.push_back(p);
    if (recent_.size() > kRecentProfiles) recent_.pop_front();
    profile_ = std::move(p);
  }

  std::string status_json(const laserline::status_t& s) const;
  std::string profile_json(const laserline::profile_t& p, std::int64_t cloud_after,
                           std::int64_t* cloud_sent) const;
  std::string frame_json(const laserline::image_t& image) const;
  std::string viewer_json() const;

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  bool stopping_ = false;
  Channel channels_[kChannels];
  std::string last_problem_;
  std::shared_ptr<const laserline::profile_t> profile_;
  std::shared_ptr<const laserline::image_t> image_;
  std::shared_ptr<const laserline::status_t> status_;
  std::int64_t profile_count_ = 0, image_count_ = 0, status_count_ = 0;
  std::deque<std::shared_ptr<const laserline::profile_t>> recent_;
  std::deque<CloudChunk> cloud_;
  Clock::duration history_;
  const Clock::time_point started_ = Clock::now();

  // Only the LCM thread touches these.
  laserline::messages::Limits limits_;
  laserline::messages::ProblemLog problems_{"laserline-view: "};

  std::mutex encode_mutex_;  // one encoder at a time; readers of the cache take mutex_
  std::shared_ptr<const EncodedFrame> encoded_;
};

std::string LiveState::status_json(const laserline::status_t& s) const {
  char instance[24];
  std::snprintf(instance, sizeof instance, "%016llx",
                static_cast<unsigned long long>(s.instance_id));
  JsonObject o;
  o.integer("utime", s.utime)
      .integer("uptime_us", s.uptime_us)
      .string("camera_backend", s.camera_backend)
      .string("detector", s.detector)
      .string("camera_state", s.camera_state)
      .boolean("laser_on", s.laser_on)
      .integer("laser_switches", s.laser_switches)
      .integer("frames_captured", s.frames_captured)
      .integer("frames_processed", s.frames_processed)
      .integer("frames_dropped", s.frames_dropped)
      .integer("profiles_published", s.profiles_published)
      .integer("profiles_dropped", s.profiles_dropped)
      .integer("images_published", s.images_published)
      .integer("images_dropped", s.images_dropped)
      .integer("grab_timeouts", s.grab_timeouts)
      .integer("grab_errors", s.grab_errors)
      .integer("publish_errors", s.publish_errors)
      .integer("laser_safety_offs", s.laser_safety_offs)
      .integer("laser_errors", s.laser_errors)
      .number("frame_rate_hz", s.frame_rate_hz, 2)
      .number("points_per_profile", s.points_per_profile, 1)
      .integer("latency_samples", s.latency_samples)
      .number("latency_p50_ms", s.latency_p50_ms, 2)
      .number("latency_p99_ms", s.latency_p99_ms, 2)
      .number("latency_max_ms", s.latency_max_ms, 2)
      .number("pipeline_p50_ms", s.pipeline_p50_ms, 2)
      .number("pipeline_p99_ms", s.pipeline_p99_ms, 2)
      .number("pipeline_max_ms", s.pipeline_max_ms, 2)
      .number("cpu_percent", s.cpu_percent, 1)
      .integer("frames_over_budget", s.frames_over_budget)
      .number("processing_max_ms", s.processing_max_ms, 2)
      .integer("laser_late_switches", s.laser_late_switches)
      .integer("camera_reconnects", s.camera_reconnects)
      .integer("camera_missing_packets", s.camera_missing_packets)
      .integer("camera_timeouts", s.camera_timeouts)
      .integer("camera_size_mismatches", s.camera_size_mismatches)
      .integer("camera_underruns", s.camera_underruns)
      .integer("camera_other_errors", s.camera_other_errors)
      .integer("camera_skipped_frames", s.camera_skipped_frames)
      .integer("bad_messages", s.bad_messages)
      .integer("bad_frames", s.bad_frames)
      .string("instance_id", instance);
  return o.str();
}

// Points in the camera frame (mm) for the plot, and the 3-D chunks after `cloud_after`.
std::string LiveState::profile_json(const laserline::profile_t& p, std::int64_t cloud_after,
                                    std::int64_t* cloud_sent) const {
  std::vector<float> xz, candidates_xz, uv;
  std::int64_t valid = 0;
  for (const auto& pt : p.points) {
    if (pt.valid) ++valid;
    uv.push_back(static_cast<float>(pt.u));
    uv.push_back(pt.v);
    if (!std::isfinite(pt.xyz[0]) || !std::isfinite(pt.xyz[2])) continue;
    auto& out = pt.valid ? xz : candidates_xz;
    out.push_back(pt.xyz[0] * 1000.0f);
    out.push_back(pt.xyz[2] * 1000.0f);
  }
  std::string cloud = "[";
  for (const auto& chunk : cloud_) {
    if (chunk.index <= cloud_after) continue;
    if (cloud.size() > 1) cloud += ',';
    // Ages by exposure time from the newest profile, and that one's by the clock here (a replay's
    // or another computer's clock is not this one's).
    const CloudChunk& newest = cloud_.back();
    const double age_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - newest.received).count() +
        std::max(0.0, static_cast<double>(newest.utime - chunk.utime) * 1e-3);
    cloud += JsonObject().number("age_ms", age_ms, 0).raw("xyz", numbers(chunk.xyz_mm, 0)).str();
    *cloud_sent = chunk.index;
  }
  cloud += "]";
  JsonObject o;
  o.integer("sequence", p.sequence)
      .integer("utime", p.utime)
      .boolean("laser_on", p.laser_on)
      .string("detector", p.detector)
      .integer("width", p.width)
      .integer("height", p.height)
      .integer("points", p.num_points)
      .integer("valid", valid)
      .raw("xz", numbers(xz, 1))
      .raw("candidates_xz", numbers(candidates_xz, 1))
      .raw("cloud", cloud);
  // Pixels where nothing is triangulated: the plot shows the line in the image then.
  if (xz.empty() && candidates_xz.empty()) o.raw("uv", numbers(uv, 2));
  return o.str();
}

// The frame's description and its profile's points in the frame's own pixels.
std::string LiveState::frame_json(const laserline::image_t& image) const {
  const laserline::profile_t* match = nullptr;
  for (const auto& p : recent_) {
    if (p->sequence == image.sequence) match = p.get();
  }
  std::vector<float> points, candidates;
  if (match != nullptr) {
    // Points are in full-frame pixels; the frame may be a region, downscaled by block means
    // (a block's centre is at k*i + (k-1)/2).
    const double k = image.downscale > 1 ? image.downscale : 1;
    const double x0 = image.roi_x + (k - 1) / 2, y0 = image.roi_y + (k - 1) / 2;
    for (const auto& pt : match->points) {
      const double x = match->search_origin[0] + pt.u * match->search_line_step[0] +
                       pt.v * match->search_along[0];
      const double y = match->search_origin[1] + pt.u * match->search_line_step[1] +
                       pt.v * match->search_along[1];
      auto& out = pt.valid ? points : candidates;
      out.push_back(static_cast<float>((x - x0) / k));
      out.push_back(static_cast<float>((y - y0) / k));
    }
  }
  JsonObject o;
  o.integer("sequence", image.sequence)
      .integer("utime", image.utime)
      .boolean("laser_on", image.laser_on)
      .integer("width", image.width)
      .integer("height", image.height)
      .boolean("profile", match != nullptr)
      .raw("points", numbers(points, 1))
      .raw("candidates", numbers(candidates, 1));
  return o.str();
}

std::string LiveState::viewer_json() const {
  const auto now = Clock::now();
  std::string channels = "[";
  for (const auto& c : channels_) {
    if (channels.size() > 1) channels += ',';
    const double age_s = c.received > 0 ? std::chrono::duration<double>(now - c.last).count() : NAN;
    channels += JsonObject()
                    .string("name", c.name)
                    .integer("received", c.received)
                    .integer("malformed", c.malformed)
                    .number("age_s", age_s, 1)
                    .str();
  }
  channels += "]";
  return JsonObject()
      .raw("channels", channels)
      .string("last_problem", last_problem_)
      .integer("streams", open_streams_)
      .number("uptime_s", std::chrono::duration<double>(now - started_).count(), 0)
      .number("history_s", std::chrono::duration<double>(history_).count(), 1)
      .str();
}

std::string LiveState::Stream::next(bool* stopping) {
  std::unique_lock<std::mutex> lock(state_.mutex_);
  std::string out;
  auto event = [&out](const char* name, const std::string& data) {
    out += "event: ";
    out += name;
    out += "\ndata: ";
    out += data;
    out += "\n\n";
  };
  if (!started_) {
    started_ = true;
    out += "retry: 2000\n\n";
  }
  const auto give_up = Clock::now() + std::chrono::seconds(1);
  while (true) {
    if (state_.stopping_) {
      *stopping = true;
      return "";
    }
    const auto now = Clock::now();
    if (now >= next_viewer_) {
      event("viewer", state_.viewer_json());
      next_viewer_ = now + std::chrono::seconds(1);
    }
    if (state_.status_ && state_.status_count_ != status_sent_) {
      event("status", state_.status_json(*state_.status_));
      status_sent_ = state_.status_count_;
    }
    if (state_.profile_ && state_.profile_count_ != profile_sent_ && now >= next_profile_) {
      event("profile", state_.profile_json(*state_.profile_, cloud_sent_, &cloud_sent_));
      profile_sent_ = state_.profile_count_;
      next_profile_ = now + profile_period_;
    }
    if (state_.image_ && state_.image_count_ != frame_sent_ && now >= next_frame_) {
      event("frame", state_.frame_json(*state_.image_));
      frame_sent_ = state_.image_count_;
      next_frame_ = now + frame_period_;
    }
    if (!out.empty() || now >= give_up) return out;
    // Until something arrives, or what arrived earlier becomes due.
    auto wake = std::min(give_up, next_viewer_);
    if (state_.profile_count_ != profile_sent_) wake = std::min(wake, next_profile_);
    if (state_.image_count_ != frame_sent_) wake = std::min(wake, next_frame_);
    const std::int64_t seen = state_.profile_count_ + state_.image_count_ + state_.status_count_;
    state_.changed_.wait_until(lock, wake, [&] {
      return state_.stopping_ ||
             state_.profile_count_ + state_.image_count_ + state_.status_count_ != seen;
    });
  }
}

std::shared_ptr<const EncodedFrame> LiveState::frame_jpeg(std::string* problem) {
  std::shared_ptr<const laserline::image_t> image;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    image = image_;
    if (!image) {
      *problem = "no raw frame received yet on " + channels_[kImage].name;
      return nullptr;
    }
    if (encoded_ && encoded_->sequence == image->sequence) return encoded_;
  }
  std::lock_guard<std::mutex> encoding(encode_mutex_);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (encoded_ && encoded_->sequence == image->sequence) return encoded_;
  }
  cv::Mat pixels;
  if (!laserline::messages::unpack_image(*image, limits_, cv::IMREAD_UNCHANGED, &pixels, problem)) {
    *problem =
        channels_[kImage].name + ": frame " + std::to_string(image->sequence) + ": " + *problem;
    return nullptr;
  }
  if (pixels.depth() == CV_16U) pixels.convertTo(pixels, CV_8U, 1.0 / 256.0);
  auto encoded = std::make_shared<EncodedFrame>();
  encoded->sequence = image->sequence;
  std::vector<unsigned char> bytes;
  if (!cv::imencode(".jpg", pixels, bytes, {cv::IMWRITE_JPEG_QUALITY, kJpegQuality})) {
    *problem = "frame " + std::to_string(image->sequence) + " does not encode as JPEG";
    return nullptr;
  }
  encoded->jpeg.assign(bytes.begin(), bytes.end());
  std::lock_guard<std::mutex> lock(mutex_);
  encoded_ = encoded;
  return encoded;
}

// --- Command line ---------------------------------------------------------------------------

struct ListenAddress {
  std::string host;
  int port = 0;
};

bool parse_listen(const std::string& text, ListenAddress* out) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size()) return false;
  std::string host = text.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  const std::string port = text.substr(colon + 1);
  if (port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos) return false;
  const int value = std::stoi(port);
  if (value > 65535) return false;
  out->host = host;
  out->port = value;
  return true;
}

// Why `host:port` cannot be bound (httplib says only that it failed).
std::string bind_problem(const ListenAddress& where) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  const int gai =
      getaddrinfo(where.host.c_str(), std::to_string(where.port).c_str(), &hints, &found);
  if (gai != 0) return std::string("cannot resolve the address: ") + gai_strerror(gai);
  std::string problem = "cannot bind";
  for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) {
      problem = std::string("cannot bind: ") + std::strerror(errno);
      continue;
    }
    const int yes = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    const bool bound = bind(fd, a->ai_addr, a->ai_addrlen) == 0 && listen(fd, 1) == 0;
    if (!bound) problem = std::string("cannot bind: ") + std::strerror(errno);
    close(fd);
    if (bound) {
      problem = "cannot bind (the port was busy a moment ago)";
      break;
    }
  }
  freeaddrinfo(found);
  return problem;
}

double positive_number(laserline::cli::Arguments& args, const char* what) {
  const std::string text = args.value();
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !(value > 0) || !std::isfinite(value)) {
    args.fail(args.name() + ": expected " + what + " > 0, got '" + text + "'");
  }
  return value;
}

std::string content_type(std::string_view path) {
  auto ends_with = [&](std::string_view suffix) {
    return path.size() >= suffix.size() && path.substr(path.size() - suffix.size()) == suffix;
  };
  if (ends_with(".html")) return "text/html; charset=utf-8";
  if (ends_with(".js")) return "text/javascript; charset=utf-8";
  if (ends_with(".css")) return "text/css; charset=utf-8";
  return "application/octet-stream";
}

// Sends the page's commands to the daemon and waits for their answers. Thread context: send()
// from the HTTP threads, on_ack() from the LCM thread.
class CommandRelay {
 public:
  CommandRelay(lcm::LCM& lcm, std::string channel, std::string token)
      : lcm_(lcm), channel_(std::move(channel)), token_(std::move(token)) {}

  // The daemon's answer, or none within kCommandTimeout.
  std::optional<laserline::command_ack_t> send(const std::string& name, const std::string& value) {
    laserline::command_t command;
    command.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count();
    command.sender = "laserline-view";
    command.name = name;
    command.value = value;
    command.token = token_;
    std::unique_lock lock(mutex_);
    command.id = static_cast<std::int64_t>(random_() >> 1);
    waiting_[command.id];
    lock.unlock();
    lcm_.publish(channel_, &command);
    lock.lock();
    const bool answered = answered_.wait_for(
        lock, kCommandTimeout, [&] { return waiting_[command.id].has_value() || stopping_; });
    std::optional<laserline::command_ack_t> ack = std::move(waiting_[command.id]);
    waiting_.erase(command.id);
    if (!answered) ack.reset();
    return ack;
  }

  void on_ack(const lcm::ReceiveBuffer* rbuf) {
    laserline::command_ack_t ack;
    std::string problem;
    if (!laserline::messages::decode(rbuf->data, rbuf->data_size, &ack, {}, &problem)) return;
    {
      std::lock_guard lock(mutex_);
      const auto waiting = waiting_.find(ack.id);
      if (waiting == waiting_.end()) return;  // another sender's
      waiting->second = std::move(ack);
    }
    answered_.notify_all();
  }

  void stop() {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    answered_.notify_all();
  }

  bool token_is(const std::string& token) const { return token == token_; }

 private:
  lcm::LCM& lcm_;
  std::string channel_;
  std::string token_;
  std::mutex mutex_;
  std::condition_variable answered_;
  std::map<std::int64_t, std::optional<laserline::command_ack_t>> waiting_;
  std::mt19937_64 random_{std::random_device{}()};
  bool stopping_ = false;
};

void on_command_ack(const lcm::ReceiveBuffer* rbuf, const std::string&, CommandRelay* relay) {
  relay->on_ack(rbuf);
}

void on_lcm_message(const lcm::ReceiveBuffer* rbuf, const std::string& channel, LiveState* state) {
  state->on_message(rbuf, channel);
}

int run_view(int argc, char** argv) {
  const char* env_url = std::getenv("LCM_DEFAULT_URL");
  std::string url = env_url != nullptr ? env_url : "udpm://239.255.76.67:7667?ttl=0";
  std::string profile_channel = "LASERLINE_PROFILE", image_channel = "LASERLINE_IMAGE",
              status_channel = "LASERLINE_STATUS";
  ListenAddress listen_at{"127.0.0.1", 8090};
  std::string listen_text = "127.0.0.1:8090";
  double history_s = 5, frame_rate_hz = 5, profile_rate_hz = 10;
  bool allow_control = false;
  std::string token, command_channel = "LASERLINE_COMMAND";
  laserline::cli::Arguments args(argc, argv, "laserline-view", kUsage,
                                 {{"listen", true},
                                  {"url", true},
                                  {"profile-channel", true},
                                  {"image-channel", true},
                                  {"status-channel", true},
                                  {"history", true},
                                  {"frame-rate", true},
                                  {"profile-rate", true},
                                  {"allow-control", false},
                                  {"token", true},
                                  {"command-channel", true}});
  while (args.next()) {
    const std::string& arg = args.name();
    if (arg == "--listen") {
      listen_text = args.value();
      if (!parse_listen(listen_text, &listen_at)) {
        args.fail("--listen: expected ADDR:PORT (e.g. 127.0.0.1:8090), got '" + listen_text + "'");
      }
    } else if (arg == "--url") {
      url = args.value();
    } else if (arg == "--profile-channel") {
      profile_channel = args.value();
    } else if (arg == "--image-channel") {
      image_channel = args.value();
    } else if (arg == "--status-channel") {
      status_channel = args.value();
    } else if (arg == "--history") {
      history_s = positive_number(args, "seconds");
    } else if (arg == "--frame-rate") {
      frame_rate_hz = positive_number(args, "frames per second");
    } else if (arg == "--profile-rate") {
      profile_rate_hz = positive_number(args, "profiles per second");
    } else if (arg == "--allow-control") {
      allow_control = true;
    } else if (arg == "--token") {
      token = args.value();
      if (token.empty() || token.size() > 255) args.fail("--token: 1 to 255 characters");
    } else if (arg == "--command-channel") {
      command_channel = args.value();
    } else {
      args.fail("unexpected argument '" + args.value() + "'");
    }
  }
  if (allow_control && token.empty()) {
    args.fail("--allow-control needs --token: nobody switches the laser without it");
  }
  if (!allow_control && !token.empty()) args.fail("--token goes with --allow-control");
  if (url.rfind("file://", 0) == 0) {
    args.fail("--url: a log is not live; replay it with lcm-logplayer and view that");
  }

  // Signals go to the thread that waits for them; every other thread blocks them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  signal(SIGPIPE, SIG_IGN);

  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::fprintf(stderr, "laserline-view: --url: cannot open LCM '%s'\n", url.c_str());
    return 1;
  }
  LiveState state(profile_channel, image_channel, status_channel, history_s);
  for (const std::string& channel : {profile_channel, image_channel, status_channel}) {
    lcm.subscribeFunction(channel, &on_lcm_message, &state);
  }
  CommandRelay relay(lcm, command_channel, token);
  if (allow_control) lcm.subscribeFunction(command_channel + "_ACK", &on_command_ack, &relay);

  httplib::Server server;
  server.new_task_queue = [] { return new httplib::ThreadPool(kHttpThreads); };
  // SO_REUSEADDR (a restart binds at once) but not httplib's default SO_REUSEPORT, with which a
  // second laserline-view on the same port would start silently and take half the connections.
  server.set_socket_options([](socket_t sock) {
    const int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  // Scripts and styles from this program only; nothing else is loaded or contacted.
  server.set_default_headers(
      {{"Content-Security-Policy", "default-src 'self'; img-src 'self' data:; connect-src 'self'"},
       {"X-Content-Type-Options", "nosniff"}});
  for (const laserline::view::Asset& asset : laserline::view::assets()) {
    const std::string type = content_type(asset.path);
    const std::string body(asset.body);
    auto serve = [type, body](const httplib::Request&, httplib::Response& res) {
      res.set_content(body, type);
    };
    server.Get(std::string(asset.path), serve);
    if (asset.path == "/index.html") server.Get("/", serve);
  }
  // Whether the page shows its controls.
  server.Get("/control", [allow_control](const httplib::Request&, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    res.set_content(allow_control ? "{\"allowed\": true}" : "{\"allowed\": false}",
                    "application/json");
  });
  // Commands only with --allow-control, each with the token given there.
  if (allow_control) {
    server.Post("/command", [&relay](const httplib::Request& req, httplib::Response& res) {
      auto reply = [&res](int status, bool accepted, const std::string& name,
                          const std::string& value, const std::string& old_value,
                          const std::string& reason) {
        std::string json = "{\"accepted\": ";
        json += accepted ? "true" : "false";
        for (const auto& [key, text] :
             {std::pair{"name", &name}, std::pair{"value", &value},
              std::pair{"old_value", &old_value}, std::pair{"reason", &reason}}) {
          json += std::string(", \"") + key + "\": ";
          append_string(json, *text);
        }
        json += "}";
        res.status = status;
        res.set_header("Cache-Control", "no-store");
        res.set_content(json, "application/json");
      };
      const std::string name = req.get_param_value("name");
      if (!relay.token_is(req.get_param_value("token"))) {
        reply(403, false, name, "", "", "token: not the one laserline-view was started with");
        return;
      }
      if (name.empty() || name.size() > 255 || req.get_param_value("value").size() > 255) {
        reply(400, false, name, "", "", "name: 1 to 255 characters, value: at most 255");
        return;
      }
      const auto ack = relay.send(name, req.get_param_value("value"));
      if (!ack) {
        reply(504, false, name, "", "", "no answer from the daemon within 3 s");
        return;
      }
      reply(200, ack->accepted, ack->name, ack->value, ack->old_value, ack->reason);
    });
  }
  // Everything else is GET only: the view watches.
  server.Get("/frame.jpg", [&state](const httplib::Request&, httplib::Response& res) {
    std::string problem;
    const auto frame = state.frame_jpeg(&problem);
    if (!frame) {
      res.status = 503;
      res.set_content(problem + "\n", "text/plain");
      return;
    }
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Laserline-Sequence", std::to_string(frame->sequence));
    res.set_content(frame->jpeg, "image/jpeg");
  });
  server.Get("/events", [&](const httplib::Request&, httplib::Response& res) {
    if (state.open_streams_.fetch_add(1) >= kMaxStreams) {
      state.open_streams_.fetch_sub(1);
      res.status = 503;
      res.set_content("laserline-view: " + std::to_string(kMaxStreams) +
                          " live views are open already; close one\n",
                      "text/plain");
      return;
    }
    res.set_header("Cache-Control", "no-store");
    auto stream = std::make_shared<LiveState::Stream>(state, frame_rate_hz, profile_rate_hz);
    res.set_chunked_content_provider(
        "text/event-stream",
        [stream](std::size_t, httplib::DataSink& sink) {
          bool stopping = false;
          const std::string text = stream->next(&stopping);
          if (stopping) {
            sink.done();
            return true;
          }
          return text.empty() || sink.write(text.data(), text.size());
        },
        [&state](bool) { state.open_streams_.fetch_sub(1); });
  });

  const int port =
      listen_at.port == 0
          ? server.bind_to_any_port(listen_at.host)
          : (server.bind_to_port(listen_at.host, listen_at.port) ? listen_at.port : -1);
  if (port < 0) {
    std::fprintf(stderr, "laserline-view: --listen %s: %s\n", listen_text.c_str(),
                 bind_problem(listen_at).c_str());
    return 1;
  }
  const bool v6 = listen_at.host.find(':') != std::string::npos;
  std::printf("laserline-view: http://%s%s%s:%d/ (LCM %s; %s, %s, %s)%s\n", v6 ? "[" : "",
              listen_at.host.c_str(), v6 ? "]" : "", port, url.c_str(), profile_channel.c_str(),
              image_channel.c_str(), status_channel.c_str(),
              allow_control ? "; controls on, with the token" : "");
  std::fflush(stdout);

  std::atomic<bool> stopping{false}, lcm_failed{false};
  std::thread lcm_thread([&] {
    while (!stopping) {
      if (lcm.handleTimeout(100) < 0) {
        std::fprintf(stderr, "laserline-view: --url %s: receiving failed; stopping\n", url.c_str());
        lcm_failed = true;
        break;
      }
    }
    stopping = true;
  });
  std::thread signal_thread([&] {
    const timespec poll{0, 200'000'000};
    while (!stopping) {
      if (sigtimedwait(&stop_signals, nullptr, &poll) > 0) stopping = true;
    }
    state.stop();
    relay.stop();
    server.stop();
  });
  const bool served = server.listen_after_bind();
  stopping = true;
  state.stop();
  signal_thread.join();
  lcm_thread.join();
  return served && !lcm_failed ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_view);
}
