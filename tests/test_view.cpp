// laserline-view end to end: the real laserlined on its simulator publishing over UDP multicast in
// a private network namespace, laserline-view subscribed to it, and HTTP clients: this test's own
// (page, files, event stream, frames) and a real headless Chromium (tests/view_browser.py).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "private_network.hpp"
#include "run_command.hpp"

namespace {

std::string g_namespace_problem;
constexpr const char* kUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";
constexpr int kPort = 18090;
#ifdef LASERLINE_SANITIZED
constexpr int kSlowdown = 3;  // the daemon under the sanitizers may not reach the rate limits
#else
constexpr int kSlowdown = 1;
#endif
constexpr const char* kHost = "127.0.0.1";

// 640 x 480 frames, every third sent whole as JPEG; the projector sweeps the wall.
constexpr const char* kConfig = R"(camera:
  backend: sim
  frame_rate_hz: 30
  sim: {seed: 3, distance_m: 1.0, tilt_y_deg: 8, texture_contrast: 0.5, ambient: 60,
        laser_peak: 170, noise_sigma: 1.5, scan_rate_deg_s: 12, scan_amplitude_deg: 8}
calibration:
  camera: {width: 640, height: 480, fx: 700, fy: 700, cx: 319.5, cy: 239.5}
  laser: {baseline_m: 0.2, angle_deg: 80, sheet_width_m: 0.003}
laser: {mode: on}
detector: {name: maxvalue, maxvalue: {threshold: 60}}
lcm: {url: "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304", image_every_n: 3,
      image_downscale: 1, image_compression: jpeg, profile_points: all, status_period_s: 1.0}
)";

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

struct Event {
  std::string name, data;
};

// The events of /events for `seconds` (a stream is never "done": the client ends it).
std::vector<Event> read_events(double seconds) {
  httplib::Client client(kHost, kPort);
  client.set_read_timeout(5, 0);
  std::string text;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  client.Get("/events", [&](const char* data, std::size_t size) {
    text.append(data, size);
    return std::chrono::steady_clock::now() < end;
  });
  std::vector<Event> events;
  std::size_t at = 0;
  while (true) {
    const std::size_t blank = text.find("\n\n", at);
    if (blank == std::string::npos) break;
    const std::string block = text.substr(at, blank - at);
    at = blank + 2;
    Event e;
    std::size_t line_start = 0;
    while (line_start < block.size()) {
      std::size_t line_end = block.find('\n', line_start);
      if (line_end == std::string::npos) line_end = block.size();
      const std::string line = block.substr(line_start, line_end - line_start);
      if (line.rfind("event: ", 0) == 0) e.name = line.substr(7);
      if (line.rfind("data: ", 0) == 0) e.data = line.substr(6);
      line_start = line_end + 1;
    }
    if (!e.name.empty()) events.push_back(e);
  }
  return events;
}

int count(const std::vector<Event>& events, const std::string& name) {
  int n = 0;
  for (const auto& e : events)
    n += e.name == name ? 1 : 0;
  return n;
}

// The value after "key": (or "key": ) at or after `from` in JSON text: a string's contents or a
// number's text; empty when absent. (GCC 12 warns inside std::regex under the sanitizers.)
std::string json_value(const std::string& text, const std::string& key, std::size_t from = 0) {
  std::size_t at = text.find("\"" + key + "\":", from);
  if (at == std::string::npos) return "";
  at += key.size() + 3;
  while (at < text.size() && text[at] == ' ')
    ++at;
  if (at < text.size() && text[at] == '"') {
    const std::size_t end = text.find('"', at + 1);
    return end == std::string::npos ? "" : text.substr(at + 1, end - at - 1);
  }
  const std::size_t end = text.find_first_of(",}]", at);
  return text.substr(at, end == std::string::npos ? std::string::npos : end - at);
}

class LiveView : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!g_namespace_problem.empty()) return;
    dir_ = std::filesystem::temp_directory_path() / ("laserline_view_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
    std::ofstream(dir_ / "sim.yaml") << kConfig;
    daemon_ = laserline::test_support::spawn_tied_child(
        {LASERLINED_PATH, "--config", (dir_ / "sim.yaml").string()},
        (dir_ / "daemon.log").string());
    view_ = laserline::test_support::spawn_tied_child(
        {LASERLINE_VIEW_PATH, "--url", kUrl, "--listen",
         std::string(kHost) + ":" + std::to_string(kPort)},
        (dir_ / "view.log").string());
    // Up when the page is served and a status (1 Hz) and a frame have arrived.
    httplib::Client client(kHost, kPort);
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up) {
      const auto frame = client.Get("/frame.jpg");
      if (frame && frame->status == 200) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  static void TearDownTestSuite() {
    for (pid_t* pid : {&view_, &daemon_}) {
      if (*pid <= 0) continue;
      kill(*pid, SIGTERM);
      int status = 0;
      waitpid(*pid, &status, 0);
      if (pid == &view_) {
        EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
            << "laserline-view did not exit cleanly on SIGTERM: " << read_file(dir_ / "view.log");
      }
      *pid = -1;
    }
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }
  void SetUp() override {
    if (!g_namespace_problem.empty()) GTEST_SKIP() << g_namespace_problem;
  }
  static std::string logs() {
    return "\nlaserline-view: " + read_file(dir_ / "view.log") +
           "\nlaserlined: " + read_file(dir_ / "daemon.log");
  }

  static inline std::filesystem::path dir_;
  static inline pid_t daemon_ = -1, view_ = -1;
};

TEST_F(LiveView, PageAndItsFilesLoadFromTheProgramItself) {
  httplib::Client client(kHost, kPort);
  const auto page = client.Get("/");
  ASSERT_TRUE(page) << logs();
  EXPECT_EQ(page->status, 200);
  EXPECT_EQ(page->get_header_value("Content-Type"), "text/html; charset=utf-8");
  EXPECT_NE(page->body.find("<script src=\"view.js\"></script>"), std::string::npos);
  EXPECT_NE(page->body.find("<link rel=\"stylesheet\" href=\"view.css\">"), std::string::npos);
  EXPECT_NE(page->get_header_value("Content-Security-Policy").find("default-src 'self'"),
            std::string::npos);
  const std::pair<const char*, const char*> files[] = {
      {"/view.js", "text/javascript; charset=utf-8"}, {"/view.css", "text/css; charset=utf-8"}};
  for (const auto& [path, type] : files) {
    const auto r = client.Get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 200) << path;
    EXPECT_EQ(r->get_header_value("Content-Type"), type) << path;
    EXPECT_GT(r->body.size(), 1000u) << path;
    // Nothing is fetched from elsewhere.
    EXPECT_EQ(r->body.find("http://"), std::string::npos) << path;
    EXPECT_EQ(r->body.find("https://"), std::string::npos) << path;
  }
  EXPECT_EQ(client.Get("/no-such-file.js")->status, 404);
}

TEST_F(LiveView, EventStreamDeliversStatusProfilesAndFrames) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<Event> events = read_events(3.2);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const int statuses = count(events, "status"), profiles = count(events, "profile"),
            frames = count(events, "frame"), viewers = count(events, "viewer");
  std::printf("events in %.1f s: %d status, %d profile, %d frame, %d viewer\n", s, statuses,
              profiles, frames, viewers);
  // The latest status at once, then the daemon's 1 Hz; profiles at the 10 Hz limit of the
  // 30 Hz published; frames at the 5 Hz limit of the 10 Hz published.
  EXPECT_GE(statuses, 3 - (kSlowdown > 1 ? 1 : 0)) << logs();
  EXPECT_GE(profiles, 20 / kSlowdown) << logs();
  EXPECT_LE(profiles, 36);
  EXPECT_GE(frames, 10 / kSlowdown) << logs();
  EXPECT_LE(frames, 18);
  EXPECT_GE(viewers, 3);
  bool status_checked = false, frame_checked = false, profile_checked = false;
  for (const auto& e : events) {
    if (e.name == "status" && !status_checked) {
      status_checked = true;
      EXPECT_NE(e.data.find("\"camera_state\":\"streaming\""), std::string::npos) << e.data;
      EXPECT_NE(e.data.find("\"camera_backend\":\"sim\""), std::string::npos) << e.data;
      EXPECT_NE(e.data.find("\"latency_p99_ms\":"), std::string::npos) << e.data;
      EXPECT_NE(e.data.find("\"frames_dropped\":"), std::string::npos) << e.data;
    }
    if (e.name == "frame" && !frame_checked) {
      frame_checked = true;
      EXPECT_NE(e.data.find("\"width\":640,\"height\":480,\"roi_x\":0,\"roi_y\":0,\"downscale\":1"),
                std::string::npos)
          << e.data;
      EXPECT_NE(e.data.find("\"profile\":true"), std::string::npos) << "paired: " << e.data;
      EXPECT_EQ(e.data.find("\"points\":[]"), std::string::npos) << e.data;
    }
    if (e.name == "profile" && !profile_checked) {
      profile_checked = true;
      EXPECT_NE(e.data.find("\"detector\":\"maxvalue\""), std::string::npos) << e.data;
      EXPECT_EQ(e.data.find("\"xz\":[]"), std::string::npos) << "triangulated: " << e.data;
      EXPECT_NE(e.data.find("\"cloud\":[{\"age_ms\":"), std::string::npos) << e.data;
    }
  }
  EXPECT_TRUE(status_checked && frame_checked && profile_checked);
}

TEST_F(LiveView, FrameIsTheCamerasSizeAndChanges) {
  httplib::Client client(kHost, kPort);
  const auto first = client.Get("/frame.jpg");
  ASSERT_TRUE(first) << logs();
  ASSERT_EQ(first->status, 200) << first->body;
  EXPECT_EQ(first->get_header_value("Content-Type"), "image/jpeg");
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  const auto second = client.Get("/frame.jpg");
  ASSERT_TRUE(second && second->status == 200);
  EXPECT_NE(first->get_header_value("X-Laserline-Sequence"),
            second->get_header_value("X-Laserline-Sequence"));
  auto decode = [](const std::string& bytes) {
    return cv::imdecode(std::vector<unsigned char>(bytes.begin(), bytes.end()),
                        cv::IMREAD_UNCHANGED);
  };
  const cv::Mat a = decode(first->body), b = decode(second->body);
  ASSERT_FALSE(a.empty());
  ASSERT_FALSE(b.empty());
  EXPECT_EQ(a.cols, 640);
  EXPECT_EQ(a.rows, 480);
  EXPECT_EQ(a.type(), CV_8UC1);
  ASSERT_EQ(a.size(), b.size());
  // The projector sweeps the wall: the line moves, not only the noise.
  cv::Mat difference;
  cv::absdiff(a, b, difference);
  EXPECT_GT(cv::countNonZero(difference > 40), 200);
}

TEST_F(LiveView, MalformedMessagesAreCountedAndShownAndNothingStops) {
  {
    lcm::LCM lcm(kUrl);
    ASSERT_TRUE(lcm.good());
    const std::string garbage(100, '\x7f');
    for (int i = 0; i < 5; ++i) {
      lcm.publish("LASERLINE_PROFILE", garbage.data(), static_cast<unsigned>(garbage.size()));
      lcm.publish("LASERLINE_IMAGE", garbage.data(), 7);
    }
  }
  const std::vector<Event> events = read_events(1.5);
  EXPECT_GE(count(events, "profile"), 8) << "profiles still arrive";
  std::string viewer;
  for (const auto& e : events) {
    if (e.name == "viewer") viewer = e.data;
  }
  for (const char* channel : {"LASERLINE_PROFILE", "LASERLINE_IMAGE"}) {
    const std::size_t at = viewer.find(std::string("\"name\":\"") + channel + "\"");
    ASSERT_NE(at, std::string::npos) << viewer;
    EXPECT_EQ(json_value(viewer, "malformed", at), "5") << channel << ": " << viewer;
  }
  EXPECT_NE(viewer.find("\"last_problem\":\"LASERLINE_IMAGE: "), std::string::npos) << viewer;
  const std::string log = read_file(dir_ / "view.log");
  EXPECT_NE(log.find("laserline-view: LASERLINE_PROFILE: "), std::string::npos) << log;
}

TEST_F(LiveView, BadListenAddressAndPortInUseAreOneLine) {
  // (timeout: a second server that started would otherwise serve until the test times out)
  const std::string view =
      "timeout 10 " + std::string(LASERLINE_VIEW_PATH) + " --url '" + kUrl + "'";
  auto r = laserline::test_support::run_command(view + " --listen 8090");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out,
            "laserline-view: --listen: expected ADDR:PORT (e.g. 127.0.0.1:8090), got '8090' (see "
            "--help)\n");
  r = laserline::test_support::run_command(view + " --listen 127.0.0.1:" + std::to_string(kPort));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.out, "laserline-view: --listen 127.0.0.1:" + std::to_string(kPort) +
                       ": cannot bind: Address already in use\n");
  r = laserline::test_support::run_command(view + " --listen no.such.host.invalid:80");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("laserline-view: --listen no.such.host.invalid:80: cannot resolve"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
}

// Eight browsers watch at once; a ninth is told so, and the page still loads meanwhile.
TEST_F(LiveView, StreamsAreLimitedAndThePageStillLoads) {
  // The earlier tests' streams end when a write to them fails (within two events).
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  std::vector<std::thread> watchers;
  std::atomic<int> streaming{0};
  for (int i = 0; i < 8; ++i) {
    watchers.emplace_back([&streaming] {
      httplib::Client client(kHost, kPort);
      const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(4);
      bool counted = false;
      client.Get("/events", [&](const char*, std::size_t) {
        if (!counted) ++streaming;
        counted = true;
        return std::chrono::steady_clock::now() < end;
      });
    });
  }
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  while (streaming < 8 && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(streaming, 8);
  httplib::Client client(kHost, kPort);
  const auto ninth = client.Get("/events");
  ASSERT_TRUE(ninth);
  EXPECT_EQ(ninth->status, 503);
  EXPECT_EQ(ninth->body, "laserline-view: 8 live views are open already; close one\n");
  const auto page = client.Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  const auto frame = client.Get("/frame.jpg");
  ASSERT_TRUE(frame);
  EXPECT_EQ(frame->status, 200);
  for (auto& w : watchers)
    w.join();
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));  // for the next test's browser
}

// Chromium opens the page: no console message or failed load, the stream fills the page, and
// two screenshots seconds apart differ in the frame (saved for people to look at).
TEST_F(LiveView, ChromiumShowsTheLiveViewWithoutErrors) {
  const std::string out_dir = VIEW_SCREENSHOT_DIR;
  std::filesystem::create_directories(out_dir);
  const auto r = laserline::test_support::run_command(
      std::string("/usr/bin/python3 ") + VIEW_BROWSER_SCRIPT + " http://" + kHost + ":" +
      std::to_string(kPort) + "/ " + out_dir + " 2.5");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string skip = json_value(r.out, "skip");
  if (!skip.empty()) GTEST_SKIP() << skip;
  std::printf("%s\n", r.out.c_str());
  EXPECT_NE(r.out.find("\"problems\": []"), std::string::npos) << r.out;
  const std::string load_s = json_value(r.out, "load_s");
  ASSERT_FALSE(load_s.empty() || load_s == "null") << r.out;
  EXPECT_LT(std::stod(load_s), 5.0);
  // Both times the page had run its script, met no error, drawn frames and the status.
  struct PageState {
    int frames, profiles, statuses;
    std::string status;
  };
  std::vector<PageState> states;
  for (const char* when : {"\"first\":", "\"second\":"}) {
    const std::size_t at = r.out.find(when);
    ASSERT_NE(at, std::string::npos) << r.out;
    EXPECT_EQ(json_value(r.out, "ready", at), "1") << when;
    EXPECT_EQ(json_value(r.out, "errors", at), "0") << when;
    states.push_back({std::stoi("0" + json_value(r.out, "frames", at)),
                      std::stoi("0" + json_value(r.out, "profiles", at)),
                      std::stoi("0" + json_value(r.out, "statuses", at)),
                      json_value(r.out, "status", at)});
  }
  EXPECT_GE(states[0].frames, 3) << "frames drawn";
  EXPECT_GT(states[1].frames, states[0].frames + 3) << "frames drawn";
  EXPECT_GT(states[1].profiles, states[0].profiles) << "profiles shown";
  EXPECT_GE(states[0].statuses, 1) << "statuses shown";
  for (const auto& state : states) {
    const std::size_t rate = state.status.find("frames/s\\t");
    ASSERT_NE(rate, std::string::npos) << state.status;
    EXPECT_TRUE(std::isdigit(static_cast<unsigned char>(state.status[rate + 10]))) << state.status;
    EXPECT_NE(state.status.find("camera\\tsim, streaming"), std::string::npos) << state.status;
  }
  cv::Rect frame;
  ASSERT_EQ(std::sscanf(json_value(r.out, "rect").c_str(), "%d,%d,%d,%d", &frame.x, &frame.y,
                        &frame.width, &frame.height),
            4)
      << r.out;
  const cv::Mat a = cv::imread(out_dir + "/view_1.png"), b = cv::imread(out_dir + "/view_2.png");
  ASSERT_FALSE(a.empty());
  ASSERT_FALSE(b.empty());
  ASSERT_TRUE((frame & cv::Rect(0, 0, a.cols, a.rows)) == frame) << frame;
  cv::Mat difference;
  cv::absdiff(a(frame), b(frame), difference);
  cv::cvtColor(difference, difference, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(difference > 40), 500) << "the picture did not change";
  // The frame shows an image, not a black canvas.
  EXPECT_GT(cv::mean(a(frame))[0], 20.0);
}

// The text of `key` in the report of step `step` of view_browser.py --control.
std::string step_value(const std::string& report, int step, const std::string& key) {
  const std::size_t at = report.find("{\"step\": " + std::to_string(step) + ",");
  return at == std::string::npos ? "<no step " + std::to_string(step) + ">"
                                 : json_value(report, key, at);
}

// Controls only behind --allow-control and its token: the plain view has none; with them, a
// command without the token, or naming no setting, is refused by the view. In Chromium with the
// token, each control of the page sends its command and the daemon's answer appears: accepted
// (the exposure, a region dragged on the frame, the threshold, every value in force) or refused
// with the daemon's reason (the simulated camera's frame rate and features, a threshold out of
// range, a region beyond the frame); the profiles that follow lie inside the region.
TEST_F(LiveView, ControlsSendEachCommandOnlyWithTheToken) {
  httplib::Client plain(kHost, kPort);
  const auto not_allowed = plain.Get("/control");
  ASSERT_TRUE(not_allowed) << logs();
  EXPECT_EQ(not_allowed->body, "{\"allowed\": false}");
  const auto no_route =
      plain.Post("/command", "name=exposure_us&value=1500", "application/x-www-form-urlencoded");
  ASSERT_TRUE(no_route);
  EXPECT_EQ(no_route->status, 404);

  constexpr int kControlPort = kPort + 1;
  const pid_t view = laserline::test_support::spawn_tied_child(
      {LASERLINE_VIEW_PATH, "--url", kUrl, "--listen",
       std::string(kHost) + ":" + std::to_string(kControlPort), "--allow-control", "--token",
       "t0ken"},
      (dir_ / "view-control.log").string());
  httplib::Client client(kHost, kControlPort);
  std::string allowed;
  for (int i = 0; i < 100 && allowed.empty(); ++i) {
    if (const auto r = client.Get("/control"); r && r->status == 200) {
      allowed = r->body;
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  EXPECT_EQ(allowed, "{\"allowed\": true}") << read_file(dir_ / "view-control.log");
  const auto no_token =
      client.Post("/command", "name=laser.mode&value=off", "application/x-www-form-urlencoded");
  ASSERT_TRUE(no_token);
  EXPECT_EQ(no_token->status, 403);
  EXPECT_EQ(json_value(no_token->body, "reason"),
            "token: not the one laserline-view was started with");
  for (const char* name : {"exposure", "genicam:", "laser"}) {
    const auto unknown =
        client.Post("/command", std::string("name=") + name + "&value=1&token=t0ken",
                    "application/x-www-form-urlencoded");
    ASSERT_TRUE(unknown);
    EXPECT_EQ(unknown->status, 400) << name;
    EXPECT_EQ(json_value(unknown->body, "reason")
                  .rfind(std::string("name: '") + name + "' is not a setting the page sends (", 0),
              0u)
        << unknown->body;
  }

  // Around the middle of the frame, where the swept line is.
  constexpr int kX = 160, kY = 40, kWidth = 320, kHeight = 400;
  const std::string region = "160,40,320,400";
  const std::string steps = R"([
    {"fields": {"exposure": "1700"}, "click": "set-exposure"},
    {"fields": {"frame-rate": "20"}, "click": "set-frame-rate"},
    {"fields": {"threshold": "300"}, "click": "set-threshold"},
    {"fields": {"roi-x": "600", "roi-y": "0", "roi-w": "80", "roi-h": "10"}, "click": "set-roi"},
    {"drag": [160, 40, 480, 440]},
    {"click": "set-roi", "settle_s": 1.5, "screenshot": "controls.png"},
    {"fields": {"feature-prefix": "genicam:", "feature-name": "Gain", "feature-value": "3"},
     "click": "set-feature"},
    {"fields": {"threshold": "70", "exposure": ""}, "click": "set-threshold"},
    {"click": "get-all"}])";
  const std::string out_dir = VIEW_SCREENSHOT_DIR;
  std::filesystem::create_directories(out_dir);
  const auto r = laserline::test_support::run_command(
      std::string("/usr/bin/python3 ") + VIEW_BROWSER_SCRIPT + " http://" + kHost + ":" +
      std::to_string(kControlPort) + "/ " + out_dir + " 1 --control t0ken '" + steps + "'");
  // The frames (and their profiles' points) the view shows with the region in force.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const std::vector<Event> events = read_events(1.5);
  // Back as it was for the rest of the suite, and the view stopped.
  std::vector<std::string> restored;
  for (const char* setting : {"name=detector.roi&value=full", "name=exposure_us&value=1000",
                              "name=detector.maxvalue.threshold&value=60"}) {
    const auto answer = client.Post("/command", std::string(setting) + "&token=t0ken",
                                    "application/x-www-form-urlencoded");
    restored.push_back(answer ? answer->body : "no answer");
  }
  kill(view, SIGTERM);
  waitpid(view, nullptr, 0);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const std::string skip = json_value(r.out, "skip");
  if (!skip.empty()) GTEST_SKIP() << skip;
  std::printf("%s\n", r.out.c_str());
  EXPECT_NE(r.out.find("\"problems\": []"), std::string::npos) << r.out;
  const std::size_t control = r.out.find("\"control\":");
  ASSERT_NE(control, std::string::npos) << r.out;
  EXPECT_EQ(json_value(r.out, "shown", control), "true") << r.out;
  struct Expected {
    int step;
    const char* css_class;
    std::string text;  // the start of the answer's text
  };
  const Expected expected[] = {
      {0, "ok", "exposure_us = 1700 (was "},
      {1, "bad",
       "refused: frame_rate_hz: the simulated camera's frame rate is its scene's time base, "
       "fixed at start (camera.frame_rate_hz)"},
      {2, "bad",
       "refused: detector.maxvalue.threshold: must be between 1 and 255, got 300 (in force: "
       "60)"},
      {3, "bad",
       "refused: detector.roi: [600, 0, 80, 10] reaches beyond the 640x480 frame (in force: "
       "0,0,640,480)"},
      {5, "ok", "detector.roi = " + region + " (was 0,0,640,480)"},
      {6, "bad",
       "refused: genicam:Gain: not a setting of the simulated camera (exposure_us, gain_db)"},
      {7, "ok", "detector.maxvalue.threshold = 70 (was 60)"},
      {8, "ok", "in force: exposure_us=1700 "},
  };
  for (const Expected& e : expected) {
    EXPECT_EQ(step_value(r.out, e.step, "acks"), std::to_string(e.step < 4 ? e.step + 1 : e.step))
        << "step " << e.step << ": " << r.out;
    EXPECT_EQ(step_value(r.out, e.step, "class"), e.css_class) << "step " << e.step;
    EXPECT_EQ(step_value(r.out, e.step, "text").substr(0, e.text.size()), e.text)
        << "step " << e.step;
  }
  // The drag filled the region's fields; "get" filled every field with the values in force.
  EXPECT_EQ(step_value(r.out, 4, "region"), region) << r.out;
  EXPECT_NE(
      step_value(r.out, 8, "text").find(" detector.maxvalue.threshold=70 detector.roi=" + region),
      std::string::npos)
      << r.out;
  EXPECT_EQ(step_value(r.out, 8, "exposure"), "1700") << r.out;

  int frames = 0, points = 0;
  for (const auto& e : events) {
    if (e.name != "frame" || e.data.find("\"profile\":true") == std::string::npos) continue;
    ++frames;
    const std::size_t list = e.data.find("\"points\":[");
    ASSERT_NE(list, std::string::npos) << e.data;
    std::istringstream in(e.data.substr(list + 10, e.data.find(']', list) - list - 10));
    double u = 0, v = 0;
    char comma = 0;
    while (in >> u) {
      in >> comma >> v;
      in >> comma;
      ++points;
      const long row = std::lround(v);
      EXPECT_TRUE(u >= kX && u < kX + kWidth && row >= kY && row < kY + kHeight)
          << "point " << u << ", " << v << " outside " << region << ": " << e.data.substr(0, 200);
    }
  }
  std::printf("with the region in force: %d frames, %d points\n", frames, points);
  EXPECT_GE(frames, 3 / kSlowdown) << logs();
  EXPECT_GT(points, frames * kWidth / 2) << "the line within the region";
  EXPECT_EQ(json_value(restored[0], "value"), "0,0,640,480") << restored[0];
  EXPECT_EQ(json_value(restored[1], "value"), "1000") << restored[1];
  EXPECT_EQ(json_value(restored[2], "value"), "60") << restored[2];
}

}  // namespace

int main(int argc, char** argv) {
  // Before any thread exists: unshare(CLONE_NEWUSER) requires a single-threaded process.
  g_namespace_problem = laserline::test::enter_private_network();
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
