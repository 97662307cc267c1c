#include "hal/registry.hpp"

#include <cstdio>
#include <cstdlib>
#include <map>
#include <utility>

namespace laserline::hal {

namespace {

template <typename Factory>
using Table = std::map<std::string, Factory>;

// Function-local statics: built on first use, so registrations from static constructors of other
// files find them whatever the order in which the files are initialised.
Table<CameraFactory>& camera_table() {
  static Table<CameraFactory> table;
  return table;
}

Table<LaserFactory>& laser_table() {
  static Table<LaserFactory> table;
  return table;
}

template <typename Factory>
void add(Table<Factory>& table, const char* kind, const char* name, Factory create) {
  if (!table.emplace(name, std::move(create)).second) {
    std::fprintf(stderr, "laserline: two %s backends are registered as '%s'\n", kind, name);
    std::abort();
  }
}

template <typename Factory>
std::vector<std::string> names(const Table<Factory>& table) {
  std::vector<std::string> list;
  for (const auto& entry : table)
    list.push_back(entry.first);
  return list;
}

template <typename Factory>
const Factory* find(const Table<Factory>& table, const std::string& name) {
  const auto it = table.find(name);
  return it != table.end() ? &it->second : nullptr;
}

}  // namespace

CameraBackendRegistration::CameraBackendRegistration(const char* name, CameraFactory create) {
  add(camera_table(), "camera", name, std::move(create));
}

LaserBackendRegistration::LaserBackendRegistration(const char* name, LaserFactory create) {
  add(laser_table(), "laser", name, std::move(create));
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
