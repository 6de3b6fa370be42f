#pragma once
// `tessera devices`: the OpenNI2 devices this host can open, with the modes they offer.
#include <string>
#include <vector>

namespace tessera::drivers::openni2 {

struct VideoModeDescription {
  std::string sensor;  // "depth", "colour" or "ir"
  int width = 0;
  int height = 0;
  int fps = 0;
  std::string pixel_format;  // "depth 1 mm", "RGB888", ...
};

struct DeviceDescription {
  std::string uri;  // pass as openni2://URI
  std::string name;
  std::string vendor;
  int usb_vendor_id = 0;
  int usb_product_id = 0;
  bool hardware_registration = false;
  std::vector<VideoModeDescription> modes;
  std::string problem;  // non-empty when the device is listed but could not be opened
};

// Every device OpenNI2's drivers report. Throws core::SourceError when OpenNI2 cannot start.
std::vector<DeviceDescription> listDevices();

std::string pixelFormatName(int oni_pixel_format);

}  // namespace tessera::drivers::openni2
