// laserline-listen: subscribes to a laserline daemon over LCM and reports what it received:
// profiles, points per profile, latency, status, and an overlay PNG of the last raw frame with
// the points of the same frame drawn on it.
#include <signal.h>
#include <time.h>
#include <laserline/calibration_t.hpp>
#include <laserline/image_t.hpp>
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "lcmtypes/checked_decode.hpp"
#include "lcmtypes/lcm_log.hpp"
#include "tools/cli.hpp"

namespace {

constexpr const char* kUsage =
    "usage: laserline-listen [--url URL] [--duration S] [--quiet S] [--overlay FILE.png]\n"
    "                        [--profile-channel C] [--image-channel C] [--status-channel C]\n"
    "                        [--calibration-channel C]\n"
    "  --url URL        LCM URL (default: LCM_DEFAULT_URL or udpm://239.255.76.67:7667?ttl=0)\n"
    "  --duration S     stop after S seconds (default: run until --quiet or SIGINT)\n"
    "  --quiet S        stop when nothing arrived for S seconds after the first message (default "
    "2)\n"
    "  --overlay FILE   write the last raw frame with its profile's points drawn on it\n"
    "A log (--url file://PATH) is read here to its end, on through damaged records (each reported\n"
    "with its byte offsets); since the point is to read the whole log, the exit status is 1 when\n"
    "the log was damaged or cut short or held messages that do not decode, as it is when no\n"
    "profile arrived. Messages that do not decode are counted and reported at a limited rate;\n"
    "two daemons publishing on one channel (two instance ids) are reported.\n";

volatile sig_atomic_t g_stop = 0;
void on_signal(int) {
  g_stop = 1;
}

double now_s(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

// A live daemon's frames are dropped long before this age (its frame timeout, the rings): an
// older exposure time is a replay's, or another computer's clock.
constexpr double kReplayedAfterMs = 10'000;
// How long a live listener waits for a first message before it says why nothing may come.
constexpr double kSilenceWarningS = 3.0;

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return NAN;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(values.size() - 1) + 0.5);
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

struct Listener {
  std::int64_t profiles = 0;
  std::int64_t first_sequence = -1, last_sequence = -1, sequence_gaps = 0, sequence_reversals = 0;
  std::int64_t first_utime = 0, last_utime = 0, utime_reversals = 0;
  std::vector<double> points_per_profile;
  std::vector<double> receive_latency_ms;   // exposure (utime) -> received here, wall clocks
  std::deque<laserline::profile_t> recent;  // to pair a raw frame with its profile
  std::optional<laserline::image_t> last_image;
  std::int64_t images = 0;
  std::vector<laserline::status_t> statuses;
  double last_message_s = 0;
  std::int64_t decode_errors = 0;
  laserline::messages::Limits limits;
  laserline::messages::ProblemLog problems{"laserline-listen: "};
  std::map<std::string, std::set<std::int64_t>> instances;  // ids seen per channel
  std::int64_t calibrations = 0;                            // calibration_t messages
  std::set<std::int64_t> published_calibration_ids;         // in calibration_t
  std::set<std::int64_t> profile_calibration_ids;           // named by profiles
  double last_exposure_us = NAN, last_gain_db = NAN;

  // Messages from the network or a log: (bytes, receive time, channel, where for reports).
  struct Message {
    const void* data;
    std::size_t size;
    std::int64_t recv_utime;
    const std::string& channel;
    const std::string& where;
  };

  template <typename Type>
  bool decode(const Message& m, Type* out) {
    std::string problem;
    if (laserline::messages::decode(m.data, m.size, out, limits, &problem)) return true;
    ++decode_errors;
    problems.report(m.channel, m.where + ": " + problem + "; skipped");
    return false;
  }

  void note_instance(const std::string& channel, std::int64_t id) {
    std::set<std::int64_t>& ids = instances[channel];
    if (ids.size() >= 16 || !ids.insert(id).second || ids.size() != 2) return;
    std::fprintf(stderr,
                 "laserline-listen: %s: messages from two daemons (instance ids %016llx and "
                 "%016llx): two laserlined publish on the same channels\n",
                 channel.c_str(), static_cast<unsigned long long>(*ids.begin()),
                 static_cast<unsigned long long>(*ids.rbegin()));
  }

  void handle_profile(const Message& m) {
    laserline::profile_t p;
    if (!decode(m, &p)) return;
    note_instance(m.channel, p.instance_id);
    last_message_s = now_s(CLOCK_MONOTONIC);
    receive_latency_ms.push_back(static_cast<double>(m.recv_utime - p.utime) / 1000.0);
    if (profiles > 0) {
      if (p.sequence <= last_sequence) ++sequence_reversals;
      if (p.sequence > last_sequence + 1) sequence_gaps += p.sequence - last_sequence - 1;
      if (p.utime <= last_utime) ++utime_reversals;
    } else {
      first_sequence = p.sequence;
      first_utime = p.utime;
    }
    last_sequence = p.sequence;
    last_utime = p.utime;
    ++profiles;
    if (profile_calibration_ids.size() < 16) profile_calibration_ids.insert(p.calibration_id);
    last_exposure_us = p.exposure_us;
    last_gain_db = p.gain_db;
    points_per_profile.push_back(p.num_points);
    recent.push_back(std::move(p));
    if (recent.size() > 256) recent.pop_front();
  }

  void handle_image(const Message& m) {
    laserline::image_t image;
    if (!decode(m, &image)) return;
    last_message_s = now_s(CLOCK_MONOTONIC);
    ++images;
    last_image = std::move(image);
  }

  void handle_status(const Message& m) {
    laserline::status_t s;
    if (!decode(m, &s)) return;
    note_instance(m.channel, s.instance_id);
    last_message_s = now_s(CLOCK_MONOTONIC);
    statuses.push_back(std::move(s));
  }

  void handle_calibration(const Message& m) {
    laserline::calibration_t c;
    if (!decode(m, &c)) return;
    note_instance(m.channel, c.instance_id);
    last_message_s = now_s(CLOCK_MONOTONIC);
    ++calibrations;
    if (published_calibration_ids.size() < 16) published_calibration_ids.insert(c.calibration_id);
  }

  // LCM's subscription handlers (plain functions: GCC's UBSan misreports LCM's
  // member-function-pointer dispatch).
  static Message live(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    return {rbuf->data, rbuf->data_size, rbuf->recv_utime, channel, channel};
  }
  static void on_profile(const lcm::ReceiveBuffer* rbuf, const std::string& c, Listener* self) {
    self->handle_profile(live(rbuf, c));
  }
  static void on_image(const lcm::ReceiveBuffer* rbuf, const std::string& c, Listener* self) {
    self->handle_image(live(rbuf, c));
  }
  static void on_status(const lcm::ReceiveBuffer* rbuf, const std::string& c, Listener* self) {
    self->handle_status(live(rbuf, c));
  }
  static void on_calibration(const lcm::ReceiveBuffer* rbuf, const std::string& c, Listener* self) {
    self->handle_calibration(live(rbuf, c));
  }
};

bool write_overlay(const Listener& l, const std::string& path) {
  if (!l.last_image) {
    std::printf("  overlay: not written, no raw frame received\n");
    return false;
  }
  const laserline::image_t& img = *l.last_image;
  if (img.pixelformat != laserline::image_t::PIXEL_FORMAT_GRAY) {
    std::printf("  overlay: not written, the raw frame is not 8-bit grey\n");
    return false;
  }
  cv::Mat gray;
  std::string problem;
  if (!laserline::messages::unpack_image(img, l.limits, cv::IMREAD_GRAYSCALE, &gray, &problem) ||
      gray.type() != CV_8UC1) {
    std::printf("  overlay: not written, the raw frame (compression %d) does not decode: %s\n",
                static_cast<int>(img.compression), problem.c_str());
    return false;
  }
  // Points are in full-frame pixels; the frame may be a region, downscaled by block means
  // (a block's centre is at k*i + (k-1)/2).
  const double k = img.downscale > 1 ? img.downscale : 1;
  const double x0 = img.roi_x + (k - 1) / 2, y0 = img.roi_y + (k - 1) / 2;
  cv::Mat overlay;
  cv::cvtColor(gray, overlay, cv::COLOR_GRAY2BGR);
  const laserline::profile_t* match = nullptr;
  for (const auto& p : l.recent) {
    if (p.sequence == img.sequence) match = &p;
  }
  int drawn = 0, rejected = 0;
  if (match != nullptr) {
    constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
    for (const auto& pt : match->points) {
      // The point's frame pixel, from the profile's search axes (see point_t).
      const double x = match->search_origin[0] + pt.u * match->search_line_step[0] +
                       pt.v * match->search_along[0];
      const double y = match->search_origin[1] + pt.u * match->search_line_step[1] +
                       pt.v * match->search_along[1];
      const cv::Point centre(static_cast<int>(std::lround((x - x0) / k * 16.0)),
                             static_cast<int>(std::lround((y - y0) / k * 16.0)));
      // Valid points red, rejected candidates blue.
      const cv::Scalar colour = pt.valid ? cv::Scalar(0, 0, 255) : cv::Scalar(255, 128, 0);
      // Half a pixel: the point marks the centre and leaves the line's flanks visible.
      cv::circle(overlay, centre, 1 << (kShift - 1), colour, cv::FILLED, cv::LINE_AA, kShift);
      ++(pt.valid ? drawn : rejected);
    }
  }
  if (!cv::imwrite(path, overlay)) {
    std::printf("  overlay: could not write %s\n", path.c_str());
    return false;
  }
  std::printf("  overlay: %s (frame %lld, %d points in red, %d rejected candidates in blue)\n",
              path.c_str(), static_cast<long long>(img.sequence), drawn, rejected);
  return true;
}

std::string id_list(const std::set<std::int64_t>& ids) {
  std::string text;
  for (std::int64_t id : ids) {
    char hex[20];
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(id));
    text += (text.empty() ? "" : ", ") + std::string(hex);
  }
  return text;
}

// Which calibration made the points: the ids published on the calibration channel and those the
// profiles name, which must be the same one.
void report_calibration(const Listener& l, const std::string& channel) {
  const std::string published = id_list(l.published_calibration_ids);
  if (l.calibrations == 0) {
    std::printf(
        "  calibration: none received on %s%s\n", channel.c_str(),
        l.profiles > 0 ? ("; profiles name " + id_list(l.profile_calibration_ids)).c_str() : "");
  } else {
    std::printf("  calibration: %s (%lld calibration_t messages on %s)\n", published.c_str(),
                static_cast<long long>(l.calibrations), channel.c_str());
  }
  if (l.calibrations > 0 && l.profiles > 0 &&
      l.profile_calibration_ids != l.published_calibration_ids) {
    std::printf("  calibration mismatch: profiles name %s, %s carries %s\n",
                id_list(l.profile_calibration_ids).c_str(), channel.c_str(), published.c_str());
  }
  if (l.profiles > 0) {
    auto value = [](double v, const char* unit) {
      if (std::isnan(v)) return std::string("not reported");
      char text[32];
      std::snprintf(text, sizeof text, "%g %s", v, unit);
      return std::string(text);
    };
    std::printf("  exposure, gain (last profile): %s, %s\n",
                value(l.last_exposure_us, "us").c_str(), value(l.last_gain_db, "dB").c_str());
  }
}

void report(const Listener& l, const std::string& url, const std::string& calibration_channel) {
  std::printf("laserline-listen: received on %s\n", url.c_str());
  const double span_s = static_cast<double>(l.last_utime - l.first_utime) * 1e-6;
  std::printf("  profiles: %lld (sequence %lld..%lld, %lld missing, %lld out of order), %.1f Hz\n",
              static_cast<long long>(l.profiles), static_cast<long long>(l.first_sequence),
              static_cast<long long>(l.last_sequence), static_cast<long long>(l.sequence_gaps),
              static_cast<long long>(l.sequence_reversals),
              span_s > 0 ? static_cast<double>(l.profiles - 1) / span_s : 0.0);
  if (!l.points_per_profile.empty()) {
    double sum = 0;
    for (double n : l.points_per_profile)
      sum += n;
    std::printf("  points per profile: mean %.1f, min %.0f, max %.0f\n",
                sum / static_cast<double>(l.points_per_profile.size()),
                *std::min_element(l.points_per_profile.begin(), l.points_per_profile.end()),
                *std::max_element(l.points_per_profile.begin(), l.points_per_profile.end()));
    const double p50 = percentile(l.receive_latency_ms, 0.5);
    const double p99 = percentile(l.receive_latency_ms, 0.99);
    const double max = *std::max_element(l.receive_latency_ms.begin(), l.receive_latency_ms.end());
    if (url.rfind("file://", 0) == 0) {
      // A log's event times are when its logger received each message: the latency there.
      std::printf(
          "  latency exposure -> logged (the log's own times): p50 %.2f ms, p99 %.2f ms, max "
          "%.2f ms\n",
          p50, p99, max);
    } else if (std::fabs(p50) > kReplayedAfterMs) {
      std::printf(
          "  latency exposure -> received here: not meaningful, the exposure times are %.1f s "
          "from this computer's clock (a replayed log, or clocks not synchronised); "
          "--url file://LOG gives a log's own latency\n",
          p50 * 1e-3);
    } else {
      std::printf("  latency exposure -> received here: p50 %.2f ms, p99 %.2f ms, max %.2f ms\n",
                  p50, p99, max);
    }
  }
  if (!l.statuses.empty()) {
    std::vector<double> p50, p99, pipe50, pipe99;
    double worst = 0, pipe_worst = 0;
    for (const auto& s : l.statuses) {
      if (s.latency_samples == 0) continue;
      p50.push_back(s.latency_p50_ms);
      p99.push_back(s.latency_p99_ms);
      worst = std::max(worst, static_cast<double>(s.latency_max_ms));
      pipe50.push_back(s.pipeline_p50_ms);
      pipe99.push_back(s.pipeline_p99_ms);
      pipe_worst = std::max(pipe_worst, static_cast<double>(s.pipeline_max_ms));
    }
    const auto& s = l.statuses.back();
    std::printf(
        "  latency exposure -> published (daemon status): p50 %.2f ms, p99 %.2f ms (worst second), "
        "max %.2f ms\n",
        percentile(p50, 0.5), p99.empty() ? NAN : *std::max_element(p99.begin(), p99.end()), worst);
    std::printf(
        "  latency frame arrival -> published (daemon status): p50 %.2f ms, p99 %.2f ms (worst "
        "second), max %.2f ms\n",
        percentile(pipe50, 0.5),
        pipe99.empty() ? NAN : *std::max_element(pipe99.begin(), pipe99.end()), pipe_worst);
    std::printf(
        "  status: %zu messages; last: camera %s, %lld frames captured, %lld processed, %lld "
        "dropped, %lld grab timeouts, laser %s, %lld bad input messages, %lld bad frames\n",
        l.statuses.size(), s.camera_state.c_str(), static_cast<long long>(s.frames_captured),
        static_cast<long long>(s.frames_processed), static_cast<long long>(s.frames_dropped),
        static_cast<long long>(s.grab_timeouts), s.laser_on ? "on" : "off",
        static_cast<long long>(s.bad_messages), static_cast<long long>(s.bad_frames));
  } else {
    std::printf("  status: none received\n");
  }
  if (l.statuses.empty()) {
    std::printf("  raw frames: %lld\n", static_cast<long long>(l.images));
  } else {
    // The daemon's own count of what it could not publish: a recording missing them does not
    // replay whole.
    const auto& s = l.statuses.back();
    std::printf("  raw frames: %lld received; daemon: %lld published, %lld dropped\n",
                static_cast<long long>(l.images), static_cast<long long>(s.images_published),
                static_cast<long long>(s.images_dropped));
  }
  report_calibration(l, calibration_channel);
  if (l.decode_errors > 0) {
    std::printf("  undecodable messages: %lld\n", static_cast<long long>(l.decode_errors));
  }
  for (const auto& [channel, ids] : l.instances) {
    if (ids.size() > 1) {
      std::printf("  %s: messages from %zu daemons (instance ids)\n", channel.c_str(), ids.size());
    }
  }
}

// Reads a log to its end (LCM's own file:// reader stops at the first damaged record without a
// word); false when it cannot be opened. *damaged: the log was damaged or cut short.
bool read_log(const std::string& path, Listener& listener, const std::string& profile_channel,
              const std::string& image_channel, const std::string& status_channel,
              const std::string& calibration_channel, bool* damaged) {
  laserline::messages::LcmLogReader log;
  std::string error;
  if (!log.open(path, &error)) {
    std::fprintf(stderr, "laserline-listen: --url: %s\n", error.c_str());
    return false;
  }
  laserline::messages::LcmLogReader::Event event;
  laserline::messages::LcmLogReader::Damage damage;
  while (g_stop == 0) {
    const bool more = log.next(&event, &damage);
    // Through the problem log: a log damaged all over gives a few lines, not one per region.
    if (damage.bytes > 0 && more) {
      listener.problems.report(
          "log damage",
          path + ": bytes " + std::to_string(damage.offset) + ".." +
              std::to_string(damage.offset + damage.bytes - 1) + " are damaged (" +
              std::to_string(damage.bytes) + " bytes, " + std::to_string(damage.records) +
              " records); skipped, reading resumes at event " + std::to_string(event.number) +
              " at byte " + std::to_string(event.offset));
    } else if (damage.bytes > 0) {
      listener.problems.report("log end", path +
                                              ": the log ends inside an event or in damage: the "
                                              "last " +
                                              std::to_string(damage.bytes) + " bytes (from byte " +
                                              std::to_string(damage.offset) +
                                              ") are not a complete event (recording cut short?)");
    }
    if (!more) break;
    const std::string where = path + ": event " + std::to_string(event.number) + " at byte " +
                              std::to_string(event.offset) + " on " + event.channel;
    const Listener::Message m{event.data.data(), event.data.size(), event.utime, event.channel,
                              where};
    if (event.channel == profile_channel) {
      listener.handle_profile(m);
    } else if (event.channel == image_channel) {
      listener.handle_image(m);
    } else if (event.channel == status_channel) {
      listener.handle_status(m);
    } else if (event.channel == calibration_channel) {
      listener.handle_calibration(m);
    }
  }
  *damaged = log.totals().damaged_regions > 0;
  if (*damaged) {
    std::fprintf(stderr, "laserline-listen: %s: %s\n", path.c_str(), log.damage_summary().c_str());
  }
  return true;
}

int run_listen(int argc, char** argv) {
  const char* env_url = std::getenv("LCM_DEFAULT_URL");
  std::string url = env_url != nullptr ? env_url : "udpm://239.255.76.67:7667?ttl=0";
  double duration_s = 0, quiet_s = 2.0;
  std::string overlay, profile_channel = "LASERLINE_PROFILE", image_channel = "LASERLINE_IMAGE",
                       status_channel = "LASERLINE_STATUS",
                       calibration_channel = "LASERLINE_CALIBRATION";
  laserline::cli::Arguments args(argc, argv, "laserline-listen", kUsage,
                                 {{"url", true},
                                  {"duration", true},
                                  {"quiet", true},
                                  {"overlay", true},
                                  {"profile-channel", true},
                                  {"image-channel", true},
                                  {"status-channel", true},
                                  {"calibration-channel", true}});
  while (args.next()) {
    const std::string& arg = args.name();
    auto value = [&]() -> std::string { return args.value(); };
    auto seconds = [&]() {
      const std::string text = value();
      char* end = nullptr;
      const double s = std::strtod(text.c_str(), &end);
      if (end == text.c_str() || *end != '\0' || !(s > 0) || !std::isfinite(s)) {
        std::fprintf(stderr, "laserline-listen: %s: expected seconds > 0, got '%s'\n", arg.c_str(),
                     text.c_str());
        throw laserline::cli::Exit(2);
      }
      return s;
    };
    if (arg == "--url") {
      url = value();
    } else if (arg == "--duration") {
      duration_s = seconds();
    } else if (arg == "--quiet") {
      quiet_s = seconds();
    } else if (arg == "--overlay") {
      overlay = value();
    } else if (arg == "--profile-channel") {
      profile_channel = value();
    } else if (arg == "--image-channel") {
      image_channel = value();
    } else if (arg == "--status-channel") {
      status_channel = value();
    } else if (arg == "--calibration-channel") {
      calibration_channel = value();
    } else {
      args.fail("unexpected argument '" + args.value() + "'");
    }
  }
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);

  Listener listener;
  if (url.rfind("file://", 0) == 0) {
    const std::string path = url.substr(7, url.find('?') - 7);
    bool damaged = false;
    if (!read_log(path, listener, profile_channel, image_channel, status_channel,
                  calibration_channel, &damaged)) {
      return 1;
    }
    report(listener, url, calibration_channel);
    if (!overlay.empty()) write_overlay(listener, overlay);
    return listener.profiles > 0 && !damaged && listener.decode_errors == 0 ? 0 : 1;
  }

  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::fprintf(stderr, "laserline-listen: --url: cannot open LCM '%s'\n", url.c_str());
    return 1;
  }
  lcm.subscribeFunction(profile_channel, &Listener::on_profile, &listener);
  lcm.subscribeFunction(image_channel, &Listener::on_image, &listener);
  lcm.subscribeFunction(status_channel, &Listener::on_status, &listener);
  lcm.subscribeFunction(calibration_channel, &Listener::on_calibration, &listener);

  const double start = now_s(CLOCK_MONOTONIC);
  bool warned_silence = false;
  while (g_stop == 0) {
    if (lcm.handleTimeout(100) < 0) break;
    const double now = now_s(CLOCK_MONOTONIC);
    const bool received = listener.last_message_s > 0 || listener.decode_errors > 0;
    if (!received && !warned_silence && now - start >= kSilenceWarningS) {
      warned_silence = true;
      std::fprintf(stderr,
                   "laserline-listen: nothing received on %s (%s, %s, %s) in %.0f s: is laserlined "
                   "running, with this lcm.url and these channels? from another computer its "
                   "lcm.url needs ttl=1 and this one a route for multicast (ip route add "
                   "224.0.0.0/4 dev IFACE); see docs/messages.md\n",
                   url.c_str(), profile_channel.c_str(), image_channel.c_str(),
                   status_channel.c_str(), kSilenceWarningS);
    }
    if (duration_s > 0 && now - start >= duration_s) break;
    if (listener.last_message_s > 0 && now - listener.last_message_s >= quiet_s) break;
  }
  report(listener, url, calibration_channel);
  if (!overlay.empty()) write_overlay(listener, overlay);
  return listener.profiles > 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_listen);
}
