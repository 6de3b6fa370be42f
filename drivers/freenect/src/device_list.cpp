#include <dlfcn.h>

#include <cstdlib>

#include <fmt/format.h>

#include "internal/fakenect_dump.h"
#include "internal/freenect_runtime.h"
#include "tessera/drivers/freenect/freenect_source.h"

namespace tessera::drivers::freenect {

namespace {

// Looked up at run time: fakenect lacks these functions, so a direct call would not even load.
using ListAttributes = int (*)(freenect_context*, freenect_device_attributes**);
using FreeAttributes = void (*)(freenect_device_attributes*);

std::vector<std::string> cameraSerials(freenect_context* context) {
  const auto list =
      reinterpret_cast<ListAttributes>(dlsym(RTLD_DEFAULT, "freenect_list_device_attributes"));
  const auto release =
      reinterpret_cast<FreeAttributes>(dlsym(RTLD_DEFAULT, "freenect_free_device_attributes"));
  std::vector<std::string> serials;
  if (list == nullptr || release == nullptr) return serials;
  freenect_device_attributes* attributes = nullptr;
  if (list(context, &attributes) < 0) return serials;
  for (const freenect_device_attributes* a = attributes; a != nullptr; a = a->next) {
    serials.emplace_back(a->camera_serial == nullptr ? "" : a->camera_serial);
  }
  release(attributes);
  return serials;
}

}  // namespace

std::vector<std::string> listFreenectDevices() {
  const Context context = openContext("freenect://");
  const int count = freenect_num_devices(context.get());
  const std::vector<std::string> serials = cameraSerials(context.get());
  const char* dump = std::getenv("FAKENECT_PATH");
  const bool replay = fakenectLoaded();
  std::vector<std::string> devices;
  for (int i = 0; i < count; ++i) {
    std::string line = fmt::format("freenect://{}", i);
    if (replay) {
      line +=
          fmt::format("  fakenect replay of {}", dump == nullptr ? "(FAKENECT_PATH unset)" : dump);
    } else if (static_cast<std::size_t>(i) < serials.size() && !serials[i].empty()) {
      line += fmt::format("  Kinect v1, camera serial {}", serials[static_cast<std::size_t>(i)]);
    } else {
      line += "  Kinect v1";
    }
    devices.push_back(std::move(line));
  }
  return devices;
}

}  // namespace tessera::drivers::freenect
