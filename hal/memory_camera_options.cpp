#include "hal/memory_camera.hpp"
#include "hal/registry.hpp"
#include "hal/sim/sim_camera.hpp"
#include "hal/sim/sim_options.hpp"
#include "hal/yaml_reader.hpp"

namespace laserline::hal {

std::unique_ptr<Camera> create_memory_camera(const CameraRequest& request) {
  YamlMap& camera = *request.options;
  YamlMap memory = camera.map("memory");
  MemoryCameraOptions o;
  const std::string source = memory.string("source", "sim");
  o.frames = static_cast<int>(memory.integer("frames", o.frames, 1, 100000));
  o.rate_hz = memory.number("rate_hz", camera.number("frame_rate_hz", 30.0, 0.1, 1000.0), 0.0, 1e6);
  if (o.rate_hz > 0 && o.rate_hz < 0.1) {
    memory.fail("rate_hz", "must be 0 (as fast as the frame path takes them) or 0.1 to 1000000");
  }
  o.buffers = static_cast<int>(memory.integer("buffers", o.buffers, 1, 1024));
  o.loops = memory.integer("loops", o.loops, 0, INT64_MAX / 100000);
  o.duration_s = memory.number("duration_s", o.duration_s, 0.0, 1e9);
  memory.finish();
  if (source == "sim") {
    // The scene renders lit and unlit frames itself; the memory camera looks at the laser.
    CameraRequest scene = request;
    scene.laser = nullptr;
    return std::make_unique<MemoryCamera>(o, make_sim_camera(scene), request.laser);
  }
  if (source == "memory") memory.fail("source", "must be sim or a recording backend, not memory");
  std::unique_ptr<Camera> recording = make_camera(source, request);
  if (!recording) {
    std::string names;
    for (const std::string& name : camera_backends()) {
      if (name != "memory" && name != "sim") names += (names.empty() ? "" : ", ") + name;
    }
    memory.fail("source", "unknown camera backend '" + source +
                              "' (expected sim or the backend of a recording; backends: " + names +
                              ")");
  }
  if (!recording->paced_by_consumer()) {
    memory.fail("source", "the " + source +
                              " backend as configured is a live source; frames are held from the "
                              "simulator (sim) or a recording (lcm with a file:// url)");
  }
  return std::make_unique<MemoryCamera>(o, std::move(recording));
}

namespace {
const CameraBackendRegistration kMemory{"memory", create_memory_camera};
}  // namespace

}  // namespace laserline::hal
