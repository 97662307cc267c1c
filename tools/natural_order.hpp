#pragma once

#include <string_view>

namespace laserline::tools {

// The order people number files in: runs of digits compare as numbers ("step2" before "step10",
// of any length), letters without regard to case; names equal so ("img01" and "img1", "A" and
// "a") fall back to their bytes, so that the order is total and the same on every run.
bool natural_less(std::string_view a, std::string_view b);

}  // namespace laserline::tools
