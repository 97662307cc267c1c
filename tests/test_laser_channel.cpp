// The laser channel of colour frames: names, weighted expressions and their errors.
#include "hal/laser_channel.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

namespace laserline::hal {
namespace {

void expect_weights(const std::string& text, float r, float g, float b) {
  const LaserChannel c = parse_laser_channel(text);
  EXPECT_FLOAT_EQ(c.red, r) << text;
  EXPECT_FLOAT_EQ(c.green, g) << text;
  EXPECT_FLOAT_EQ(c.blue, b) << text;
  EXPECT_EQ(c.text, text);
}

std::string error_of(const std::string& text) {
  try {
    parse_laser_channel(text);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(LaserChannel, Names) {
  expect_weights("red", 1, 0, 0);
  expect_weights("green", 0, 1, 0);
  expect_weights("blue", 0, 0, 1);
  expect_weights("grey", 0.299f, 0.587f, 0.114f);
  expect_weights("gray", 0.299f, 0.587f, 0.114f);
  EXPECT_TRUE(parse_laser_channel("red").single());
  EXPECT_FALSE(parse_laser_channel("grey").single());
  EXPECT_TRUE(LaserChannel{}.single());  // the default: green
  EXPECT_FLOAT_EQ(LaserChannel{}.green, 1.0f);
}

TEST(LaserChannel, WeightedDifferences) {
  expect_weights("red - (green + blue) / 2", 1, -0.5f, -0.5f);
  expect_weights("r-(g+b)/2", 1, -0.5f, -0.5f);
  expect_weights("1.5*red - 0.5*green", 1.5f, -0.5f, 0);
  expect_weights("green*2 - red - blue", -1, 2, -1);
  expect_weights("-blue + 2 * (green - 0.25 * red)", -0.5f, 2, -1);
  EXPECT_FALSE(parse_laser_channel("red - (green + blue) / 2").single());
}

TEST(LaserChannel, Errors) {
  EXPECT_EQ(error_of("purple"),
            "channel \"purple\": unknown name 'purple' (red, green, blue, "
            "grey) at character 1");
  EXPECT_EQ(error_of("red * green"),
            "channel \"red * green\": a product of two channels is not a weighted sum at "
            "character 12");
  EXPECT_EQ(error_of("red / green"),
            "channel \"red / green\": division by a channel is not a weighted sum at character 12");
  EXPECT_EQ(error_of("red / 0"), "channel \"red / 0\": division by zero at character 8");
  EXPECT_EQ(error_of("(red - blue"), "channel \"(red - blue\": missing ')' at character 12");
  EXPECT_EQ(error_of("red +"), "channel \"red +\": expression ends early at character 6");
  EXPECT_EQ(error_of("red green"), "channel \"red green\": unexpected 'g' at character 5");
  EXPECT_EQ(error_of("red + 10"),
            "channel \"red + 10\": a constant term is not allowed (weights of red, green and blue "
            "only)");
  EXPECT_EQ(error_of("-red"),
            "channel \"-red\": no channel has a positive weight: the laser "
            "would never be brighter than 0");
  EXPECT_EQ(error_of("100*red"), "channel \"100*red\": weights must be within -16..16");
  EXPECT_EQ(error_of(""), "channel \"\": expression ends early at character 1");
}

}  // namespace
}  // namespace laserline::hal
