// The backend registry as every program sees it: this file names no backend's code, only the
// registry, so it finds the backends only if each registered itself and the linker kept it.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "hal/registry.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {
namespace {

TEST(Registry, EveryBackendRegisteredItself) {
  EXPECT_EQ(camera_backends(),
            (std::vector<std::string>{"aravis", "lcm", "memory", "sim", "v4l2"}));
  EXPECT_EQ(laser_backends(), (std::vector<std::string>{"gpiod", "sim"}));
}

TEST(Registry, MakesARegisteredBackendByName) {
  YamlMap options(load_yaml_text("{}", "r.yaml"), "r.yaml", "laser");
  EXPECT_NE(make_laser("sim", options), nullptr);
  EXPECT_EQ(make_laser("gpio", options), nullptr);
  EXPECT_EQ(make_camera("gige", CameraRequest{}), nullptr);
}

TEST(RegistryDeathTest, ANameRegisteredTwiceAborts) {
  EXPECT_DEATH(LaserBackendRegistration("sim", [](YamlMap&) { return nullptr; }),
               "two laser backends are registered as 'sim'");
}

}  // namespace
}  // namespace laserline::hal
