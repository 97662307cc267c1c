// laserline-ctl: changes a setting of a running laserlined (laserline.command_t on
// LASERLINE_COMMAND) and prints its answer (laserline.command_ack_t) in one line: the value in
// force as the daemon read it back from the device, or why the command was refused.
//
//   laserline-ctl set exposure_us 1500
//   laserline-ctl get
//   laserline-ctl set detector.roi 100,50,400,300
//   laserline-ctl laser off
#include <unistd.h>

#include <laserline/command_ack_t.hpp>
#include <laserline/command_t.hpp>
#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "lcmtypes/checked_decode.hpp"
#include "tools/cli.hpp"

namespace {

constexpr const char* kUsage =
    "usage: laserline-ctl [OPTIONS] set NAME VALUE | get | laser on|off|alternate|pattern\n"
    "Sends one command to a running laserlined and prints its answer in one line.\n"
    "  set NAME VALUE       exposure_us, gain_db, frame_rate_hz, laser.mode,\n"
    "                       detector.maxvalue.threshold, detector.frontend.snr_threshold_db,\n"
    "                       detector.roi (x,y,width,height or full),\n"
    "                       genicam:<Feature> (aravis), v4l2:<control name> (v4l2)\n"
    "  get                  every value in force\n"
    "  laser MODE           the same as set laser.mode MODE\n"
    "  --lcm-url URL        the daemon's LCM URL (default udpm://239.255.76.67:7667?ttl=0)\n"
    "  --channel NAME       its lcm.command_channel (default LASERLINE_COMMAND)\n"
    "  --ack-channel NAME   its lcm.command_ack_channel (default: the channel + _ACK)\n"
    "  --token TEXT         its lcm.command_token, when it has one\n"
    "  --timeout SECONDS    how long to wait for the answer, 0.01 to 3600 (default 3)\n"
    "Exit status: 0 accepted, 1 refused, 2 usage, 3 no answer in time.\n";

struct Options {
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  std::string channel = "LASERLINE_COMMAND";
  std::string ack_channel;
  std::string token;
  double timeout_s = 3;
  std::string name;
  std::string value;
};

Options parse_args(int argc, char** argv) {
  Options o;
  laserline::cli::Arguments args(argc, argv, "laserline-ctl", kUsage,
                                 {{"lcm-url", true},
                                  {"channel", true},
                                  {"ack-channel", true},
                                  {"token", true},
                                  {"timeout", true}});
  std::vector<std::string> words;
  while (args.next()) {
    const std::string& name = args.name();
    if (name == "--lcm-url") {
      o.url = args.value();
    } else if (name == "--channel") {
      o.channel = args.value();
    } else if (name == "--ack-channel") {
      o.ack_channel = args.value();
    } else if (name == "--token") {
      o.token = args.value();
    } else if (name == "--timeout") {
      char* end = nullptr;
      o.timeout_s = std::strtod(args.value().c_str(), &end);
      if (end == args.value().c_str() || *end != '\0' || !(o.timeout_s >= 0.01) ||
          o.timeout_s > 3600) {
        args.fail("--timeout: expected seconds from 0.01 to 3600, got '" + args.value() + "'");
      }
    } else {
      words.push_back(args.value());
    }
  }
  if (o.ack_channel.empty()) o.ack_channel = o.channel + "_ACK";
  if (words.empty()) args.fail("no command (set, get or laser)");
  const std::string& verb = words[0];
  if (verb == "set" && words.size() == 3) {
    o.name = words[1];
    o.value = words[2];
  } else if (verb == "get" && words.size() == 1) {
    o.name = "get";
  } else if (verb == "laser" && words.size() == 2) {
    o.name = "laser.mode";
    o.value = words[1];
  } else if (verb == "set" || verb == "get" || verb == "laser") {
    args.fail(verb == "set"   ? "set takes a NAME and a VALUE"
              : verb == "get" ? "get takes nothing more"
                              : "laser takes one of on, off, alternate, pattern");
  } else {
    args.fail("unknown command '" + verb + "' (set, get or laser)");
  }
  return o;
}

struct Answer {
  std::int64_t id = 0;
  bool received = false;
  laserline::command_ack_t ack;
};

void on_ack(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Answer* answer) {
  laserline::command_ack_t ack;
  std::string problem;
  if (!laserline::messages::decode(rbuf->data, rbuf->data_size, &ack, {}, &problem)) {
    std::fprintf(stderr, "laserline-ctl: %s: %s; skipped\n", channel.c_str(), problem.c_str());
    return;
  }
  if (ack.id != answer->id || answer->received) return;  // another sender's
  answer->ack = ack;
  answer->received = true;
}

std::string sender_name() {
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) != 0) host[0] = '\0';
  return std::string("laserline-ctl@") + host + "[" + std::to_string(getpid()) + "]";
}

int run_ctl(int argc, char** argv) {
  const Options o = parse_args(argc, argv);
  lcm::LCM lcm(o.url);
  if (!lcm.good()) {
    std::fprintf(stderr, "laserline-ctl: --lcm-url: cannot open '%s'\n", o.url.c_str());
    return 2;
  }
  Answer answer;
  answer.id = static_cast<std::int64_t>(std::random_device{}() & 0x7fffffff) << 31 ^
              static_cast<std::int64_t>(std::random_device{}() & 0x7fffffff);
  lcm.subscribeFunction(o.ack_channel, &on_ack, &answer);

  laserline::command_t command;
  command.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
  command.id = answer.id;
  command.sender = sender_name();
  command.name = o.name;
  command.value = o.value;
  command.token = o.token;
  if (lcm.publish(o.channel, &command) != 0) {
    std::fprintf(stderr, "laserline-ctl: %s: cannot send on '%s'\n", o.url.c_str(),
                 o.channel.c_str());
    return 3;
  }
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::microseconds(static_cast<std::int64_t>(o.timeout_s * 1e6));
  while (!answer.received) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    if (lcm.handleTimeout(static_cast<int>(left.count())) < 0) break;
  }
  if (!answer.received) {
    std::fprintf(stderr,
                 "laserline-ctl: no answer on %s within %g s (is laserlined running on %s with "
                 "lcm.command_channel %s?)\n",
                 o.ack_channel.c_str(), o.timeout_s, o.url.c_str(), o.channel.c_str());
    return 3;
  }
  const laserline::command_ack_t& ack = answer.ack;
  if (!ack.accepted) {
    // The value that stays in force, where the daemon says it (the operator's next try starts
    // from it).
    if (ack.value.empty()) {
      std::printf("refused: %s\n", ack.reason.c_str());
    } else {
      std::printf("refused: %s (in force: %s)\n", ack.reason.c_str(), ack.value.c_str());
    }
    return 1;
  }
  if (o.name == "get") {
    std::printf("%s\n", ack.value.c_str());
  } else {
    std::printf("%s = %s (was %s)\n", ack.name.c_str(), ack.value.c_str(), ack.old_value.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return laserline::cli::run(argc, argv, run_ctl);
}
