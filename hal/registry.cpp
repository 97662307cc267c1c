#include "hal/registry.hpp"

#include <utility>

#include "hal/aravis_camera.hpp"
#include "hal/gpio_laser.hpp"
#include "hal/memory_camera.hpp"
#include "hal/sim/sim_options.hpp"
#include "hal/v4l2_camera.hpp"

namespace laserline::hal {

namespace {

template <typename Factory>
struct Entry {
  std::string name;
  Factory create;
};

template <typename Factory>
using Table = std::vector<Entry<Factory>>;

Table<CameraFactory>& camera_table() {
  static Table<CameraFactory> table = {
      {"sim", create_sim_camera},
      {"aravis", create_aravis_camera},
      {"v4l2", create_v4l2_camera},
      {"memory", create_memory_camera},
  };
  return table;
}

Table<LaserFactory>& laser_table() {
  static Table<LaserFactory> table = {
      {"sim", create_sim_laser},
      {"gpiod", create_gpio_laser},
  };
  return table;
}

template <typename Factory>
void add(Table<Factory>& table, const std::string& name, Factory create) {
  for (const auto& e : table) {
    if (e.name == name) return;
  }
  table.push_back({name, std::move(create)});
}

template <typename Factory>
std::vector<std::string> names(const Table<Factory>& table) {
  std::vector<std::string> list;
  for (const auto& e : table)
    list.push_back(e.name);
  return list;
}

template <typename Factory>
const Factory* find(const Table<Factory>& table, const std::string& name) {
  for (const auto& e : table) {
    if (e.name == name) return &e.create;
  }
  return nullptr;
}

}  // namespace

void register_camera_backend(const std::string& name, CameraFactory create) {
  add(camera_table(), name, std::move(create));
}

void register_laser_backend(const std::string& name, LaserFactory create) {
  add(laser_table(), name, std::move(create));
}

std::vector<std::string> camera_backends() {
  return names(camera_table());
}

std::vector<std::string> laser_backends() {
  return names(laser_table());
}

std::unique_ptr<Camera> make_camera(const std::string& backend, const CameraRequest& request) {
  const CameraFactory* create = find(camera_table(), backend);
  return create != nullptr ? (*create)(request) : nullptr;
}

std::unique_ptr<Laser> make_laser(const std::string& backend, YamlMap& options) {
  const LaserFactory* create = find(laser_table(), backend);
  return create != nullptr ? (*create)(options) : nullptr;
}

}  // namespace laserline::hal
