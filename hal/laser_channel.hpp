#pragma once

#include <string>

namespace laserline::hal {

// Which light of a colour frame is the laser's: a weighted sum of the red, green and blue
// channels, clipped to 0..255. A single channel picks the laser's colour (green for the default
// 535 nm laser, red for the red lasers common on desks); a weighted difference such as
// red - (green + blue) / 2 also cancels white ambient light, which is equally bright in all three.
// Mono frames are taken as they are whatever the channel.
struct LaserChannel {
  float red = 0.0f;
  float green = 1.0f;
  float blue = 0.0f;
  std::string text = "green";  // as the user wrote it, for messages

  // The weight of exactly one channel is 1 and the others 0.
  bool single() const;
};

// "red", "green", "blue", "grey" (or "gray": luma, ITU-R BT.601 weights) or a linear expression
// of red, green and blue with numbers, + - * / and parentheses, e.g. "red - (green + blue) / 2"
// or "1.5*red - 0.5*green". Names may be abbreviated to r, g, b. Throws std::invalid_argument
// with a one-line reason (what is wrong and where in the text).
LaserChannel parse_laser_channel(const std::string& text);

}  // namespace laserline::hal
