// The camera's strobe on a GPIO input (laser.strobe_line) through the real libgpiod 1.6 and the
// stand-in chip of tests/standins/gpiochip_shim.cpp, linked in: the test drives the strobe line's
// edges with exact timestamps (laserline_gpio_shim_drive_input), as the kernel stamps them.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "hal/clock.hpp"
#include "hal/gpio_laser.hpp"
#include "hal/gpio_strobe.hpp"
#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

extern "C" int laserline_gpio_shim_drive_input(unsigned offset, int physical_level,
                                               long long mono_ns);

namespace laserline {
namespace {

constexpr std::int64_t kUs = 1'000;
constexpr std::int64_t kMs = 1'000'000;
constexpr unsigned kStrobeOffset = 3;  // SPARE0,SPARE1,LASER_EN,STROBE
const char* const kLines = "SPARE0,SPARE1,LASER_EN,STROBE";

std::filesystem::path g_dir;

// Each test its own pin log; the shim reads it when the chip is next opened.
std::filesystem::path use_log(const std::string& name) {
  const std::filesystem::path log = g_dir / (name + ".pins");
  setenv("LASERLINE_GPIO_SHIM_LOG", log.c_str(), 1);
  return log;
}

hal::GpioStrobeOptions strobe_options(const std::string& chip, const std::string& name,
                                      bool active_low = false) {
  hal::GpioStrobeOptions o;
  o.line = hal::GpioLineAddress{chip, -1, name};
  o.active_low = active_low;
  return o;
}

bool wait_for_exposures(const hal::ExposureHistory& history, std::uint64_t count) {
  for (int i = 0; i < 2000 && history.completed() < count; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return history.completed() >= count;
}

TEST(GpioStrobe, ReadsEachEdgeWithItsKernelTimestamp) {
  use_log("timestamps");
  for (bool active_low : {false, true}) {
    hal::GpioStrobe strobe(strobe_options("gpiochip0", "STROBE", active_low));
    std::string error;
    ASSERT_TRUE(strobe.open(&error)) << error;
    EXPECT_EQ(strobe.describe(), "line 'STROBE' of gpiochip0 (laserline-shim)");
    const int active = active_low ? 0 : 1;
    if (active_low) {
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, 1, 1), 0);  // idle high
    }
    // Times chosen by the test, some in the past: the kernel's stamps, not the reading's.
    const std::int64_t t0 = hal::monotonic_ns() - 50 * kMs;
    std::vector<std::pair<std::int64_t, std::int64_t>> sent;
    for (int i = 0; i < 40; ++i) {  // more than the kernel's queue of 16 between two reads
      const std::int64_t start = t0 + i * 1234 * kUs + i;
      const std::int64_t end = start + 345 * kUs + 7 * i;
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, active, start), 0);
      ASSERT_EQ(laserline_gpio_shim_drive_input(kStrobeOffset, 1 - active, end), 0);
      sent.emplace_back(start, end);
    }
    ASSERT_TRUE(wait_for_exposures(strobe.history(), sent.size()))
        << strobe.history().completed() << " of " << sent.size();
    for (std::size_t i = 0; i < sent.size(); ++i) {
      hal::ExposureInterval interval;
      if (i + strobe.history().capacity() < sent.size()) continue;  // overwritten
      ASSERT_TRUE(strobe.history().get(i, &interval)) << i;
      EXPECT_EQ(interval.start_mono_ns, sent[i].first) << i << " active_low " << active_low;
      EXPECT_EQ(interval.end_mono_ns, sent[i].second) << i << " active_low " << active_low;
    }
    EXPECT_EQ(strobe.history().last_edge_mono_ns(), sent.back().second);
    EXPECT_EQ(strobe.read_errors(), 0);
    strobe.close();
    if (active_low) laserline_gpio_shim_drive_input(kStrobeOffset, 0, 0);
  }
}

TEST(GpioStrobe, MissingChipLineOrBusyLineIsOneLineNamingThem) {
  use_log("errors");
  std::string error;
  hal::GpioStrobe no_chip(strobe_options("gpiochip9", "STROBE"));
  EXPECT_FALSE(no_chip.open(&error));
  EXPECT_EQ(error,
            "strobe line 'STROBE' on chip 'gpiochip9': cannot open: No such file or directory");
  hal::GpioStrobe no_line(strobe_options("gpiochip0", "STROBE2"));
  EXPECT_FALSE(no_line.open(&error));
  EXPECT_EQ(error, "strobe line 'STROBE2' of gpiochip0 (laserline-shim): no line of that name");
  hal::GpioStrobeOptions by_offset = strobe_options("gpiochip0", "");
  by_offset.line.offset = 7;
  hal::GpioStrobe no_offset(by_offset);
  EXPECT_FALSE(no_offset.open(&error));
  EXPECT_EQ(error, "strobe line 7 of gpiochip0 (laserline-shim): the chip has only 4 lines (0..3)");

  hal::GpioStrobe holder(strobe_options("gpiochip0", "STROBE"));
  ASSERT_TRUE(holder.open(&error)) << error;
  hal::GpioStrobe second(strobe_options("gpiochip0", "STROBE"));
  EXPECT_FALSE(second.open(&error));
  EXPECT_EQ(error,
            "strobe line 'STROBE' of gpiochip0 (laserline-shim): cannot request its edge events: "
            "Device or resource busy (held by 'laserlined')");
  std::string found;
  EXPECT_FALSE(second.probe(&found, &error));
  EXPECT_EQ(error, "strobe line 'STROBE' of gpiochip0 (laserline-shim): in use by 'laserlined'");
  holder.close();
  EXPECT_TRUE(second.probe(&found, &error)) << error;
  EXPECT_EQ(found, "strobe line 'STROBE' of gpiochip0 (laserline-shim): free");
}

hal::YamlMap laser_section(const std::string& text) {
  return hal::YamlMap(hal::load_yaml_text(text, "c.yaml"), "c.yaml", "laser");
}

TEST(GpioStrobe, OptionsAreCheckedLikeTheLasersAndAbsentMeansNone) {
  auto make = [](const std::string& text) {
    hal::YamlMap map = laser_section(text);
    auto laser = hal::make_laser("gpiod", map);
    map.finish();
    return laser;
  };
  EXPECT_EQ(make("{chip: gpiochip0, line: LASER_EN}")->strobe(), nullptr);
  auto with = make("{chip: gpiochip0, line: LASER_EN, strobe_line: STROBE}");
  ASSERT_NE(with->strobe(), nullptr);
  EXPECT_EQ(with->strobe()->describe(), "line 'STROBE' of chip 'gpiochip0'");
  EXPECT_NE(make("{chip: gpiochip0, line: 2, strobe_line: 3, strobe_chip: gpiochip1, "
                 "strobe_active_low: true}")
                ->strobe(),
            nullptr);
  const std::vector<std::pair<std::string, std::string>> refused = {
      {"{chip: gpiochip0, line: 2, strobe_line: 2}",
       "laser.strobe_line: is the laser's own line (laser.line)"},
      {"{chip: gpiochip0, line: 2, strobe_line: 600}", "laser.strobe_line: offset must be 0..511"},
      {"{chip: gpiochip0, line: 2, strobe_line: ''}", "laser.strobe_line: must not be empty"},
      {"{chip: gpiochip0, line: 2, strobe_active_low: true}",
       "laser.strobe_active_low: goes with laser.strobe_line, which is not given"},
      {"{chip: gpiochip0, line: 2, strobe_chip: gpiochip1}",
       "laser.strobe_chip: goes with laser.strobe_line, which is not given"},
  };
  for (const auto& [text, expected] : refused) {
    try {
      make(text);
      ADD_FAILURE() << text << " accepted";
    } catch (const hal::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace laserline

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  laserline::g_dir =
      std::filesystem::temp_directory_path() / ("laserline_strobe_" + std::to_string(getpid()));
  std::filesystem::create_directories(laserline::g_dir);
  setenv("LASERLINE_GPIO_SHIM_LINES", laserline::kLines, 1);
  const int result = RUN_ALL_TESTS();
  std::filesystem::remove_all(laserline::g_dir);
  return result;
}
