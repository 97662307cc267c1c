// The command line every laserline program shares (tools/cli.hpp), run as the real executables:
// --help, --version, --opt=value beside --opt value, and one line for a bad option.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "run_command.hpp"

namespace {

using laserline::test_support::run_command;

struct Tool {
  const char* name;
  const char* path;
  const char* value_option;  // an option that takes a value, or nullptr
};

const std::vector<Tool>& tools() {
  static const std::vector<Tool> all = {
      {"laserlined", LASERLINED_PATH, "--config"},
      {"laserline-listen", LASERLINE_LISTEN_PATH, "--duration"},
      {"laserline-extract", LASERLINE_EXTRACT_PATH, "--calib"},
      {"laserline-calibrate", LASERLINE_CALIBRATE_PATH, "--board"},
      {"laserline-evaluate", LASERLINE_EVALUATE_PATH, "--frames"},
      {"laserline-example-subscriber", LASERLINE_EXAMPLE_SUBSCRIBER_PATH, nullptr},
      {"laserline-view", LASERLINE_VIEW_PATH, "--listen"},
      {"laserline-ctl", LASERLINE_CTL_PATH, "--timeout"},
  };
  return all;
}

TEST(Cli, HelpAndVersionEverywhere) {
  for (const Tool& tool : tools()) {
    for (const char* help : {" --help", " -h"}) {
      const auto r = run_command(std::string(tool.path) + help);
      EXPECT_EQ(r.exit_code, 0) << tool.name << help << "\n" << r.out;
      EXPECT_EQ(r.out.rfind(std::string("usage: ") + tool.name + " ", 0), 0u)
          << tool.name << help << "\n"
          << r.out;
    }
    const auto version = run_command(std::string(tool.path) + " --version");
    EXPECT_EQ(version.exit_code, 0) << tool.name;
    EXPECT_EQ(version.out, std::string(tool.name) + " " LASERLINE_VERSION "\n");
  }
}

TEST(Cli, ABadOptionIsOneLineNamingIt) {
  for (const Tool& tool : tools()) {
    const std::string prefix = std::string(tool.name) + ": ";
    for (const char* unknown : {" --frobnicate", " --frobnicate=3", " --frobnicate --help"}) {
      const auto r = run_command(std::string(tool.path) + unknown);
      EXPECT_EQ(r.exit_code, 2) << tool.name << unknown;
      EXPECT_EQ(r.out, prefix + "unknown option '--frobnicate' (see --help)\n") << unknown;
    }
    const auto flag_value = run_command(std::string(tool.path) + " --version=2");
    EXPECT_EQ(flag_value.exit_code, 2) << tool.name;
    EXPECT_EQ(flag_value.out, prefix + "--version: takes no value (see --help)\n");
    if (tool.value_option == nullptr) continue;
    const auto missing = run_command(std::string(tool.path) + " " + tool.value_option);
    EXPECT_EQ(missing.exit_code, 2) << tool.name;
    EXPECT_EQ(missing.out, prefix + tool.value_option + ": missing value (see --help)\n");
  }
}

// --opt=value reaches the option as --opt value does: the value shows in the tool's own check.
TEST(Cli, ValuesAfterAnEqualsSign) {
  const auto daemon = run_command(std::string(LASERLINED_PATH) + " --duration=soon");
  EXPECT_EQ(daemon.exit_code, 2);
  EXPECT_EQ(daemon.out,
            "laserlined: --duration: expected a number of seconds from 0.001 to 1e9, got 'soon'\n");
  const auto dir =
      std::filesystem::temp_directory_path() / ("laserline_cli_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string config = (dir / "c.yaml").string();
  std::ofstream(config) << "laser: {mode: alternate}\n";
  const auto check =
      run_command(std::string(LASERLINED_PATH) + " --check-config --config=" + config);
  EXPECT_EQ(check.exit_code, 0) << check.out;
  EXPECT_EQ(check.out, "laserlined: " + config + ": configuration is valid\n");
  std::filesystem::remove_all(dir);

  const auto listen = run_command(std::string(LASERLINE_LISTEN_PATH) + " --duration=never");
  EXPECT_EQ(listen.exit_code, 2);
  EXPECT_EQ(listen.out, "laserline-listen: --duration: expected seconds > 0, got 'never'\n");

  const auto calibrate = run_command(std::string(LASERLINE_CALIBRATE_PATH) + " --board=9");
  EXPECT_EQ(calibrate.exit_code, 2);
  EXPECT_EQ(calibrate.out.rfind("laserline-calibrate: --board: expected COLSxROWS", 0), 0u)
      << calibrate.out;
  EXPECT_NE(calibrate.out.find("got '9'"), std::string::npos) << calibrate.out;

  const auto evaluate =
      run_command(std::string(LASERLINE_EVALUATE_PATH) + " --size=64x64 --scenario=x --list");
  EXPECT_EQ(evaluate.exit_code, 0) << evaluate.out;
  EXPECT_NE(evaluate.out.find(": "), std::string::npos) << evaluate.out;
  const auto small = run_command(std::string(LASERLINE_EVALUATE_PATH) + " --frames=1");
  EXPECT_EQ(small.exit_code, 2);
  // --seed: another draw of the scenes (other texture and noise: other errors), 0 the table's.
  const std::string quick = std::string(LASERLINE_EVALUATE_PATH) +
                            " --size 320x256 --frames 3 --scenario pier --detector fir";
  const auto table = run_command(quick);
  const auto same = run_command(quick + " --seed 0");
  const auto other = run_command(quick + " --seed 12");
  EXPECT_EQ(table.exit_code, 0) << table.out;
  EXPECT_EQ(other.exit_code, 0) << other.out;
  EXPECT_EQ(same.out, table.out);
  EXPECT_NE(other.out, table.out);
  const auto negative = run_command(std::string(LASERLINE_EVALUATE_PATH) + " --seed -2");
  EXPECT_EQ(negative.exit_code, 2);
  EXPECT_EQ(negative.out, "laserline-evaluate: bad value for --seed\n");

  const auto extract = run_command(std::string(LASERLINE_EXTRACT_PATH) +
                                   " --calib=c.yaml --detector=nosuch --output=o.csv in.png");
  EXPECT_EQ(extract.exit_code, 2);
  EXPECT_EQ(extract.out.rfind("laserline-extract: --detector: unknown detector 'nosuch'", 0), 0u)
      << extract.out;
}

// The subscriber's one argument is a URL: an option is not opened as one.
TEST(Cli, ExampleSubscriberTakesOneUrl) {
  const std::string subscriber = LASERLINE_EXAMPLE_SUBSCRIBER_PATH;
  auto r = run_command(subscriber + " memq:// file:///x");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "laserline-example-subscriber: unexpected argument 'file:///x' (see --help)\n");
  r = run_command(subscriber + " 'file:///nonexistent/x.lcmlog?speed=0'");
  EXPECT_EQ(r.exit_code, 1);
  // LCM prints its own reason first.
  const std::string line =
      "laserline-example-subscriber: cannot open LCM 'file:///nonexistent/x.lcmlog?speed=0'\n";
  ASSERT_GE(r.out.size(), line.size()) << r.out;
  EXPECT_EQ(r.out.substr(r.out.size() - line.size()), line) << r.out;
}

}  // namespace
