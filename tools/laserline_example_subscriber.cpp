// laserline-example-subscriber: the smallest useful LCM subscriber of laserlined, and the starting
// point for every other process on the vehicle. Prints one line per profile and per status as
// they arrive. Every message is decoded through laserline's checked decode
// (lcmtypes/checked_decode.hpp): lcm-gen's typed subscription trusts the lengths in a message, so
// one crafted message on the multicast group could crash a subscriber; bad messages are reported
// at a limited rate and skipped. LCM's own file:// reader stops at the first damaged record of a
// log: to read a whole recording, damaged or not, use laserline-listen or laserline-log-reader.
//
//   laserline-example-subscriber [LCM URL]
//   laserline-example-subscriber 'udpm://239.255.76.67:7667?ttl=0'     # live (the default)
//   laserline-example-subscriber 'file://dive.lcmlog?speed=0'          # a recording, then exits
#include <laserline/profile_t.hpp>
#include <laserline/status_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <cmath>
#include <cstdio>
#include <string>

#include "lcmtypes/checked_decode.hpp"
#include "tools/cli.hpp"

namespace {

laserline::messages::ProblemLog g_problems("laserline-example-subscriber: ");

// Decodes a message of ours; false (reported) for one that is not valid.
template <typename Message>
bool decode(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Message* out) {
  std::string problem;
  if (laserline::messages::decode(rbuf->data, rbuf->data_size, out, {}, &problem)) return true;
  g_problems.report(channel, channel + ": " + problem + "; skipped");
  return false;
}

// Plain functions rather than member handlers: GCC 12's UBSan misreports LCM's member dispatch.
void on_profile(const lcm::ReceiveBuffer* rbuf, const std::string& channel, void*) {
  laserline::profile_t profile;
  if (!decode(rbuf, channel, &profile)) return;
  const laserline::profile_t* p = &profile;
  // Points carry their epipolar line u and sub-pixel position v along it (pixel centres at
  // integers; for SEARCH_COLUMNS the column and the row), mapped to the frame's pixel (x, y) by
  // the profile's search axes, and xyz in metres in the camera frame (NaN for rejected points and
  // where the ray misses the laser sheet).
  double x_sum = 0, y_sum = 0;
  int valid = 0;
  for (const auto& point : p->points) {
    if (!point.valid) continue;
    x_sum += p->search_origin[0] + point.u * p->search_line_step[0] + point.v * p->search_along[0];
    y_sum += p->search_origin[1] + point.u * p->search_line_step[1] + point.v * p->search_along[1];
    ++valid;
  }
  std::printf("profile %lld utime %lld laser %s: %d points, mean pixel (%.2f, %.2f)\n",
              static_cast<long long>(p->sequence), static_cast<long long>(p->utime),
              p->laser_on ? "on" : "off", p->num_points, valid > 0 ? x_sum / valid : NAN,
              valid > 0 ? y_sum / valid : NAN);
}

void on_status(const lcm::ReceiveBuffer* rbuf, const std::string& channel, void*) {
  laserline::status_t status;
  if (!decode(rbuf, channel, &status)) return;
  const laserline::status_t* s = &status;
  std::printf(
      "status: camera %s, %.1f Hz, %lld processed, %lld dropped, laser %s, latency p99 %.2f ms, "
      "CPU %.0f%%, %lld bad input messages\n",
      s->camera_state.c_str(), s->frame_rate_hz, static_cast<long long>(s->frames_processed),
      static_cast<long long>(s->frames_dropped), s->laser_on ? "on" : "off", s->latency_p99_ms,
      s->cpu_percent, static_cast<long long>(s->bad_messages + s->bad_frames));
}

constexpr const char* kUsage =
    "usage: laserline-example-subscriber [LCM_URL]\n"
    "Prints one line per laserline profile and status message until interrupted, or to the\n"
    "end of a file:// log.\n"
    "  LCM_URL  where to listen (default udpm://239.255.76.67:7667?ttl=0); e.g.\n"
    "           'file://dive.lcmlog?speed=0' reads a recording\n";

int run_example_subscriber(int argc, char** argv) {
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  int urls = 0;
  laserline::cli::Arguments args(argc, argv, "laserline-example-subscriber", kUsage, {});
  while (args.next()) {
    if (!args.name().empty() || ++urls > 1) args.fail("unexpected argument '" + args.value() + "'");
    url = args.value();
  }
  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::fprintf(stderr, "laserline-example-subscriber: cannot open LCM '%s'\n", url.c_str());
    return 1;
  }
  lcm.subscribeFunction("LASERLINE_PROFILE", &on_profile, static_cast<void*>(nullptr));
  lcm.subscribeFunction("LASERLINE_STATUS", &on_status, static_cast<void*>(nullptr));
  // handle() returns an error at the end of a file:// log; live, it waits for the next message.
  while (lcm.handle() == 0) {
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_example_subscriber);
}
