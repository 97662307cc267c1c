#pragma once

namespace laserline::daemon {

// Every thread of laserlined and its real-time priority, in one table (PX4's habit), so that
// the order is visible at a glance: the camera must never wait for the worker, the worker never
// for the publisher. SCHED_FIFO 1..99; 0 = normal scheduling. Applied only when the
// configuration says `realtime: {enabled: true}` (the service unit grants LimitRTPRIO).
struct ThreadSpec {
  const char* name;   // as shown by top -H / ps -L (at most 15 characters)
  int fifo_priority;  // SCHED_FIFO priority, 0 = SCHED_OTHER
  int nice = 0;       // for SCHED_OTHER threads: > 0 yields the CPU to everything else
};

// The camera's strobe line (laser.strobe_line): above the camera thread, so that an exposure's
// edges are in its history before the camera thread looks for them when the frame arrives.
inline constexpr ThreadSpec kStrobeThread{"ll-strobe", 70};
inline constexpr ThreadSpec kCameraThread{"ll-camera", 60};
inline constexpr ThreadSpec kWorkerThread{"ll-worker", 50};
// The worker's helpers (pipeline.worker_threads > 1; named ll-worker-1, -2, ...): a share of each
// frame's detection, the worker's own work, at its priority.
inline constexpr ThreadSpec kWorkerHelperThread{"ll-worker-", 50};
// Below the frame path, since LCM's publish takes a lock and makes a syscall (it may block, which
// never holds up camera or worker), but above every normal thread, so that profiles leave on
// time whatever else the computer does: bench_raw_frames measured p99 arrival->published with
// zlib raw frames at 10 Hz +141% over no raw frames as a normal thread, +12% at FIFO 20.
inline constexpr ThreadSpec kPublisherThread{"ll-publisher", 20};
// Raw frames (copy, downscale, compression, a large LCM publish) never delay profiles: their own
// thread, nice 10, below everything else.
inline constexpr ThreadSpec kImageThread{"ll-images", 0, 10};

}  // namespace laserline::daemon
