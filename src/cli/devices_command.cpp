#include "devices_command.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/drivers/freenect/freenect_source.h"
#include "tessera/drivers/openni2/device_list.h"

namespace tessera::cli {

CLI::App* addDevicesCommand(CLI::App& app) {
  return app.add_subcommand(
      "devices",
      "List the live devices this host can open: Kinect v1 through libfreenect (freenect://N) "
      "and OpenNI2 devices (Kinect v1, Xtion...) with their stream modes (openni2://URI). V4L2 "
      "cameras are named by their /dev/video nodes (docs/ROBOT.md)");
}

int devicesCommand() {
  try {
    const auto kinects = drivers::freenect::listFreenectDevices();
    for (const std::string& line : kinects) fmt::print("{}\n", line);
    if (kinects.empty()) fmt::print("no Kinect v1 found by libfreenect\n");
    const auto devices = drivers::openni2::listDevices();
    if (devices.empty()) {
      fmt::print(
          "no OpenNI2 device found (is it plugged in, and does the user have access to "
          "its USB device?)\n");
      return 0;
    }
    for (const auto& device : devices) {
      fmt::print("openni2://{}  {} ({}), USB {:04x}:{:04x}\n", device.uri, device.name,
                 device.vendor, device.usb_vendor_id, device.usb_product_id);
      if (!device.problem.empty()) {
        fmt::print("  {}\n", device.problem);
        continue;
      }
      fmt::print("  hardware registration of colour to depth: {}\n",
                 device.hardware_registration ? "yes" : "no");
      for (const auto& mode : device.modes) {
        fmt::print("  {:<6} {}x{}@{} {}\n", mode.sensor, mode.width, mode.height, mode.fps,
                   mode.pixel_format);
      }
    }
    return 0;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
