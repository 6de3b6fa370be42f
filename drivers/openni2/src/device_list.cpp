#include "tessera/drivers/openni2/device_list.h"

#include <OpenNI.h>
#include <fmt/format.h>

#include "tessera/drivers/oni/openni_runtime.h"

namespace tessera::drivers::openni2 {

std::string pixelFormatName(int format) {
  switch (format) {
    case openni::PIXEL_FORMAT_DEPTH_1_MM:
      return "depth 1 mm";
    case openni::PIXEL_FORMAT_DEPTH_100_UM:
      return "depth 100 um";
    case openni::PIXEL_FORMAT_SHIFT_9_2:
      return "shift 9.2";
    case openni::PIXEL_FORMAT_SHIFT_9_3:
      return "shift 9.3";
    case openni::PIXEL_FORMAT_RGB888:
      return "RGB888";
    case openni::PIXEL_FORMAT_YUV422:
      return "YUV422";
    case openni::PIXEL_FORMAT_YUYV:
      return "YUYV";
    case openni::PIXEL_FORMAT_GRAY8:
      return "gray 8";
    case openni::PIXEL_FORMAT_GRAY16:
      return "gray 16";
    case openni::PIXEL_FORMAT_JPEG:
      return "JPEG";
    default:
      return fmt::format("format {}", format);
  }
}

namespace {

void addModes(openni::Device& device, openni::SensorType type, const char* sensor,
              std::vector<VideoModeDescription>& modes) {
  const openni::SensorInfo* info = device.getSensorInfo(type);
  if (info == nullptr) return;
  const openni::Array<openni::VideoMode>& offered = info->getSupportedVideoModes();
  for (int i = 0; i < offered.getSize(); ++i) {
    modes.push_back({sensor, offered[i].getResolutionX(), offered[i].getResolutionY(),
                     offered[i].getFps(), pixelFormatName(offered[i].getPixelFormat())});
  }
}

}  // namespace

std::vector<DeviceDescription> listDevices() {
  oni::ensureOpenNi();
  openni::Array<openni::DeviceInfo> infos;
  openni::OpenNI::enumerateDevices(&infos);
  std::vector<DeviceDescription> devices;
  for (int i = 0; i < infos.getSize(); ++i) {
    DeviceDescription d;
    d.uri = infos[i].getUri();
    d.name = infos[i].getName();
    d.vendor = infos[i].getVendor();
    d.usb_vendor_id = infos[i].getUsbVendorId();
    d.usb_product_id = infos[i].getUsbProductId();
    openni::Device device;
    if (device.open(d.uri.c_str()) != openni::STATUS_OK) {
      d.problem = fmt::format("cannot be opened: {}", openni::OpenNI::getExtendedError());
    } else {
      addModes(device, openni::SENSOR_DEPTH, "depth", d.modes);
      addModes(device, openni::SENSOR_COLOR, "colour", d.modes);
      addModes(device, openni::SENSOR_IR, "ir", d.modes);
      d.hardware_registration =
          device.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR);
      device.close();
    }
    devices.push_back(std::move(d));
  }
  return devices;
}

}  // namespace tessera::drivers::openni2
