#pragma once

#include <string_view>
#include <vector>

namespace laserline::view {

// A file of laserline-view's page, compiled into the program from tools/view/.
struct Asset {
  std::string_view path;  // "/index.html"
  std::string_view body;
};

const std::vector<Asset>& assets();

}  // namespace laserline::view
