#include "drivers/v4l2_fake_device.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <thread>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace tessera::drivers::v4l2::fake {

namespace {

constexpr std::uint32_t kOffsetStride = 1u << 24;  // mmap offsets the fake hands out

std::uint8_t clampByte(double value) {
  return static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
}

}  // namespace

int FakeV4l2Device::open(const std::string& path) {
  if (path != camera_->path) return ENOENT;
  open_ = true;
  ++camera_->opens;
  format_ = {};
  format_.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  format_.fmt.pix.pixelformat = camera_->formats.empty() ? 0 : camera_->formats.front();
  fillLayout(format_.fmt.pix);
  return 0;
}

void FakeV4l2Device::close() {
  if (open_) ++camera_->closes;
  open_ = false;
}

int FakeV4l2Device::queryCapabilities(v4l2_capability& caps) {
  if (!open_) return EBADF;
  caps = {};
  std::strncpy(reinterpret_cast<char*>(caps.driver), "tessera-fake", sizeof caps.driver - 1);
  caps.device_caps = camera_->device_caps;
  caps.capabilities = camera_->device_caps | V4L2_CAP_DEVICE_CAPS;
  return 0;
}

int FakeV4l2Device::enumerateFormat(v4l2_fmtdesc& desc) {
  if (!open_) return EBADF;
  if (desc.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || desc.index >= camera_->formats.size()) {
    return EINVAL;
  }
  desc.pixelformat = camera_->formats[desc.index];
  desc.flags = desc.pixelformat == V4L2_PIX_FMT_MJPEG ? V4L2_FMT_FLAG_COMPRESSED : 0;
  return 0;
}

void FakeV4l2Device::fillLayout(v4l2_pix_format& pix) const {
  const auto& offered = camera_->formats;
  if (std::find(offered.begin(), offered.end(), pix.pixelformat) == offered.end()) {
    pix.pixelformat = offered.empty() ? 0 : offered.front();  // drivers substitute, not fail
  }
  pix.width = static_cast<std::uint32_t>(camera_->width);
  pix.height = static_cast<std::uint32_t>(camera_->height);
  pix.field = V4L2_FIELD_NONE;
  const std::uint32_t bytes_per_pixel = pix.pixelformat == V4L2_PIX_FMT_RGB24 ? 3 : 2;
  const bool compressed = pix.pixelformat == V4L2_PIX_FMT_MJPEG;
  pix.bytesperline = compressed ? 0 : pix.width * bytes_per_pixel;
  pix.sizeimage = pix.width * bytes_per_pixel * pix.height;
  if (compressed) pix.sizeimage = pix.width * pix.height * 3 + 65536;  // any JPEG fits, headers too
}

int FakeV4l2Device::getFormat(v4l2_format& format) {
  if (!open_) return EBADF;
  format = format_;
  return 0;
}

int FakeV4l2Device::tryFormat(v4l2_format& format) {
  if (!open_) return EBADF;
  if (format.type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return EINVAL;
  fillLayout(format.fmt.pix);
  return 0;
}

int FakeV4l2Device::setFormat(v4l2_format& format) {
  if (!open_) return EBADF;
  if (!buffers_.empty() || streaming_) return EBUSY;
  if (const int error = tryFormat(format)) return error;
  format_ = format;
  camera_->set_fourcc = format.fmt.pix.pixelformat;
  return 0;
}

int FakeV4l2Device::requestBuffers(v4l2_requestbuffers& request) {
  if (!open_) return EBADF;
  if (request.memory != V4L2_MEMORY_MMAP || streaming_) return EINVAL;
  if (request.count > 0 && !buffers_.empty()) return EBUSY;
  const std::uint32_t count = std::min<std::uint32_t>(request.count, 8);
  buffers_.assign(count, std::vector<std::uint8_t>(format_.fmt.pix.sizeimage));
  mapped_.assign(count, false);
  queued_flag_.assign(count, false);
  queued_.clear();
  request.count = count;
  if (count > 0) camera_->buffers_granted = count;
  return 0;
}

int FakeV4l2Device::queryBuffer(v4l2_buffer& buffer) {
  if (buffer.index >= buffers_.size() || buffer.memory != V4L2_MEMORY_MMAP) return EINVAL;
  buffer.length = static_cast<std::uint32_t>(buffers_[buffer.index].size());
  buffer.m.offset = buffer.index * kOffsetStride;
  return 0;
}

int FakeV4l2Device::map(std::uint32_t offset, std::uint32_t length, void*& start) {
  const std::uint32_t index = offset / kOffsetStride;
  if (offset % kOffsetStride != 0 || index >= buffers_.size() || length != buffers_[index].size()) {
    return EINVAL;
  }
  mapped_[index] = true;
  start = buffers_[index].data();
  ++camera_->maps;
  return 0;
}

int FakeV4l2Device::unmap(void* start, std::uint32_t length) {
  for (std::size_t i = 0; i < buffers_.size(); ++i) {
    if (buffers_[i].data() == start && mapped_[i] && buffers_[i].size() == length) {
      mapped_[i] = false;
      ++camera_->unmaps;
      return 0;
    }
  }
  return EINVAL;
}

int FakeV4l2Device::queueBuffer(v4l2_buffer& buffer) {
  if (buffer.index >= buffers_.size() || !mapped_[buffer.index] || queued_flag_[buffer.index]) {
    return EINVAL;
  }
  queued_flag_[buffer.index] = true;
  queued_.push_back(buffer.index);
  return 0;
}

int FakeV4l2Device::dequeueBuffer(v4l2_buffer& buffer) {
  if (!streaming_) return EINVAL;
  FakeCamera& camera = *camera_;
  if (camera.delivered >= camera.frames.size()) {
    return camera.ending == FakeEnding::kDisappearOnDequeue ? camera.end_errno : EAGAIN;
  }
  if (queued_.empty()) return EAGAIN;
  const std::uint32_t index = queued_.front();
  queued_.pop_front();
  queued_flag_[index] = false;
  const FakeFrame& frame = camera.frames[camera.delivered];
  std::vector<std::uint8_t>& storage = buffers_[index];
  const std::size_t used = std::min(frame.bytes.size(), storage.size());
  std::copy_n(frame.bytes.begin(), used, storage.begin());
  buffer.index = index;
  buffer.bytesused = static_cast<std::uint32_t>(used);
  buffer.flags =
      V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | (frame.flagged_error ? V4L2_BUF_FLAG_ERROR : 0);
  buffer.timestamp.tv_sec = frame.timestamp_ns / 1'000'000'000;
  buffer.timestamp.tv_usec = (frame.timestamp_ns % 1'000'000'000) / 1'000;
  buffer.sequence = static_cast<std::uint32_t>(camera.delivered);
  ++camera.delivered;
  return 0;
}

int FakeV4l2Device::streamOn() {
  if (buffers_.empty()) return EINVAL;
  streaming_ = true;
  ++camera_->streams_on;
  return 0;
}

int FakeV4l2Device::streamOff() {
  streaming_ = false;
  ++camera_->streams_off;
  return 0;
}

int FakeV4l2Device::waitForFrame(int timeout_ms, bool& ready) {
  ready = false;
  if (!streaming_) return EINVAL;
  const FakeCamera& camera = *camera_;
  if (camera.delivered < camera.frames.size()) {
    if (queued_.empty()) return EINVAL;  // the capture forgot to requeue: poll would never wake
    ready = true;
    return 0;
  }
  switch (camera.ending) {
    case FakeEnding::kDisappearOnDequeue:
      ready = true;  // POLLERR: the dequeue tells what happened
      return 0;
    case FakeEnding::kPollError:
      return camera.end_errno;
    case FakeEnding::kStall:
      std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
      return 0;
  }
  return 0;
}

DeviceFactory fakeFactory(std::vector<std::shared_ptr<FakeCamera>> cameras) {
  return [cameras](const std::string& path) -> std::unique_ptr<V4l2Device> {
    for (const auto& camera : cameras) {
      if (camera->path == path) return std::make_unique<FakeV4l2Device>(camera);
    }
    // Opening fails with ENOENT: the path matches no camera.
    return std::make_unique<FakeV4l2Device>(std::make_shared<FakeCamera>());
  };
}

std::vector<std::uint8_t> z16Bytes(const cv::Mat& depth_mm) {
  // The host is little-endian like the wire format (the driver asserts as much).
  const cv::Mat packed = depth_mm.isContinuous() ? depth_mm : depth_mm.clone();
  return std::vector<std::uint8_t>(packed.datastart, packed.dataend);
}

std::vector<std::uint8_t> rgb24Bytes(const cv::Mat& rgb) {
  const cv::Mat packed = rgb.isContinuous() ? rgb : rgb.clone();
  return std::vector<std::uint8_t>(packed.datastart, packed.dataend);
}

std::vector<std::uint8_t> yuyvBytes(const cv::Mat& rgb) {
  std::vector<std::uint8_t> bytes;
  for (int v = 0; v < rgb.rows; ++v) {
    for (int u = 0; u + 1 < rgb.cols; u += 2) {
      double y[2], cb = 0.0, cr = 0.0;
      for (int i = 0; i < 2; ++i) {
        const cv::Vec3b& p = rgb.at<cv::Vec3b>(v, u + i);
        const double r = p[0], g = p[1], b = p[2];
        y[i] = 16.0 + (65.481 * r + 128.553 * g + 24.966 * b) / 255.0;
        cb += 0.5 * (128.0 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255.0);
        cr += 0.5 * (128.0 + (112.0 * r - 93.786 * g - 18.214 * b) / 255.0);
      }
      bytes.insert(bytes.end(), {clampByte(y[0]), clampByte(cb), clampByte(y[1]), clampByte(cr)});
    }
  }
  return bytes;
}

std::vector<std::uint8_t> mjpegBytes(const cv::Mat& rgb, int quality) {
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  std::vector<std::uint8_t> bytes;
  cv::imencode(".jpg", bgr, bytes, {cv::IMWRITE_JPEG_QUALITY, quality});
  return bytes;
}

}  // namespace tessera::drivers::v4l2::fake
