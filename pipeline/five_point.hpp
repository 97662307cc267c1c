// The five-point solver of relative orientation, on its own: the camera motion estimator draws
// its RANSAC hypotheses from it (camera_motion.cpp).
#pragma once

#include <array>

namespace laserline::pipeline {

// Solutions of the five-point relative orientation problem (Nister): essential matrices E
// (row-major) with current^T E previous = 0 for the five normalised image points (x, y, 1) given.
// Returns how many (0 .. 10); no allocation.
int five_point_essentials(const std::array<std::array<double, 2>, 5>& previous,
                          const std::array<std::array<double, 2>, 5>& current,
                          std::array<std::array<double, 9>, 10>& essentials);

}  // namespace laserline::pipeline
