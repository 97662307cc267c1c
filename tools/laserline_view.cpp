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
//
// Here: the command line and the HTTP routes. What arrived and its events: view_state.hpp; the
// commands: view_command_relay.hpp.
#include <httplib.h>
#include <netdb.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <thread>

#include "tools/cli.hpp"
#include "tools/view_assets.hpp"
#include "tools/view_command_relay.hpp"
#include "tools/view_json.hpp"
#include "tools/view_state.hpp"

namespace {

using laserline::view::CommandRelay;
using laserline::view::LiveState;

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
    "  --allow-control     controls on the page: exposure, gain, frame rate, the laser's mode,\n"
    "                      the detector's threshold and region, camera features by name; each\n"
    "                      use needs the --token typed into the page (the laser: Class 3B)\n"
    "  --token TEXT        that token, also sent with each command: the daemon's\n"
    "                      lcm.command_token when it has one\n"
    "  --command-channel C the daemon's lcm.command_channel (default LASERLINE_COMMAND; answers\n"
    "                      on C_ACK)\n"
    "Open the address it prints in a browser. Everything the page needs is in this program.\n";

// How long /command waits for the daemon's answer.
constexpr std::chrono::seconds kCommandTimeout{3};

// Live streams open at once; the HTTP thread pool keeps threads for the page's files besides.
constexpr int kMaxStreams = 8;
constexpr std::size_t kHttpThreads = kMaxStreams + 4;

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
          laserline::view::append_string(json, *text);
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
      if (const std::string problem = laserline::view::relay_problem(name); !problem.empty()) {
        reply(400, false, name, "", "", problem);
        return;
      }
      const auto ack = relay.send(name, req.get_param_value("value"), kCommandTimeout);
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
