#include "tessera/drivers/v4l2/pixel_conversion.h"

#include <bit>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace tessera::drivers::v4l2 {

namespace {

// Z16, Y16 and YUYV are little-endian on the wire; the views below read them in host order.
static_assert(std::endian::native == std::endian::little, "16-bit V4L2 formats need swapping");

// A view of an uncompressed frame with the driver's row stride; empty when too few bytes.
cv::Mat rowView(const PixelFormat& format, const cv::Mat& bytes, int type, std::string& problem) {
  const std::size_t needed =
      static_cast<std::size_t>(format.bytes_per_line) * static_cast<std::size_t>(format.height);
  if (bytes.empty() || bytes.total() < needed || format.width <= 0 || format.height <= 0) {
    problem = fmt::format("{} bytes are not a {}x{} {} frame ({} bytes)", bytes.total(),
                          format.width, format.height, fourccName(format.fourcc), needed);
    return {};
  }
  return cv::Mat(format.height, format.width, type, const_cast<std::uint8_t*>(bytes.ptr()),
                 format.bytes_per_line);
}

// libjpeg decodes a truncated JPEG into a grey-filled image with only a warning, so the end
// of image marker (FF D9) is checked first. UVC cameras may pad a frame with zeros after it.
bool looksComplete(const cv::Mat& bytes) {
  const std::uint8_t* data = bytes.ptr();
  std::size_t end = bytes.total();
  while (end > 0 && data[end - 1] == 0) --end;
  return end >= 4 && data[0] == 0xFF && data[1] == 0xD8 && data[end - 2] == 0xFF &&
         data[end - 1] == 0xD9;
}

}  // namespace

cv::Mat depthToMillimetres(const PixelFormat& format, const cv::Mat& bytes, std::string& problem) {
  if (format.fourcc != V4L2_PIX_FMT_Z16 && format.fourcc != V4L2_PIX_FMT_Y16) {
    problem = fmt::format("{} is not a depth format", fourccName(format.fourcc));
    return {};
  }
  const cv::Mat view = rowView(format, bytes, CV_16UC1, problem);
  return view.empty() ? view : view.clone();
}

cv::Mat colourToRgb(const PixelFormat& format, const cv::Mat& bytes, std::string& problem) {
  cv::Mat rgb;
  switch (format.fourcc) {
    case V4L2_PIX_FMT_YUYV: {
      const cv::Mat view = rowView(format, bytes, CV_8UC2, problem);
      if (!view.empty()) cv::cvtColor(view, rgb, cv::COLOR_YUV2RGB_YUYV);
      return rgb;
    }
    case V4L2_PIX_FMT_RGB24: {
      const cv::Mat view = rowView(format, bytes, CV_8UC3, problem);
      return view.empty() ? view : view.clone();
    }
    case V4L2_PIX_FMT_MJPEG: {
      if (bytes.empty() || !looksComplete(bytes)) {
        problem = fmt::format("corrupt or truncated JPEG ({} bytes)", bytes.total());
        return {};
      }
      const cv::Mat bgr = cv::imdecode(bytes, cv::IMREAD_COLOR);
      if (bgr.empty()) {
        problem = fmt::format("corrupt JPEG ({} bytes)", bytes.total());
        return {};
      }
      if (bgr.cols != format.width || bgr.rows != format.height) {
        problem = fmt::format("JPEG is {}x{}, the stream {}x{}", bgr.cols, bgr.rows, format.width,
                              format.height);
        return {};
      }
      cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
      return rgb;
    }
    default:
      problem =
          fmt::format("{} is not a colour format tessera converts", fourccName(format.fourcc));
      return {};
  }
}

}  // namespace tessera::drivers::v4l2
