#pragma once

// Counts every allocation of the process, on every thread, while counting is on: by interposing
// the C allocator (which operator new, LCM and glib all end up in), or under a sanitizer through
// its allocation hook. Link tests/allocation_counter.cpp into the test executable.

namespace laserline::testing {

struct Allocations {
  long count = 0;
  long bytes = 0;
};

void start_counting_allocations();
Allocations stop_counting_allocations();
// Allocates and frees through new and malloc while counting: a counter that does not see these
// would prove nothing with a zero.
bool allocation_counter_works();

}  // namespace laserline::testing
