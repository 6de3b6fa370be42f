#include "tessera/drivers/v4l2/v4l2_capture.h"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"

namespace tessera::drivers::v4l2 {

namespace {

using Clock = std::chrono::steady_clock;

std::string joinNames(const std::vector<std::uint32_t>& fourccs) {
  std::string names;
  for (const std::uint32_t fourcc : fourccs) {
    names += (names.empty() ? "" : ", ") + fourccName(fourcc);
  }
  return names.empty() ? "none" : names;
}

// The errnos a node answers with once its camera is unplugged or its driver gave up.
bool deviceGone(int error) { return error == ENODEV || error == EIO || error == ENXIO; }

int bytesPerPixel(std::uint32_t fourcc) { return fourcc == V4L2_PIX_FMT_RGB24 ? 3 : 2; }

}  // namespace

const std::vector<std::uint32_t>& depthFormatPreferences() {
  static const std::vector<std::uint32_t> formats{V4L2_PIX_FMT_Z16, V4L2_PIX_FMT_Y16};
  return formats;
}

const std::vector<std::uint32_t>& colourFormatPreferences() {
  static const std::vector<std::uint32_t> formats{V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG,
                                                  V4L2_PIX_FMT_RGB24};
  return formats;
}

bool isUncompressed(std::uint32_t fourcc) {
  return fourcc != V4L2_PIX_FMT_MJPEG && fourcc != V4L2_PIX_FMT_JPEG;
}

V4l2Capture::V4l2Capture(std::unique_ptr<V4l2Device> device, CaptureConfig config)
    : device_(std::move(device)), config_(std::move(config)) {
  try {
    setUp();
  } catch (...) {
    release();  // the destructor does not run for a constructor that throws
    throw;
  }
}

V4l2Capture::~V4l2Capture() { release(); }

void V4l2Capture::setUp() {
  const std::string& path = config_.path;
  if (const int error = device_->open(path)) {
    // libv4l2 queries the capabilities while opening: ENOTTY means some other kind of file.
    throw core::SourceError(error == ENOTTY ? fmt::format("{}: not a V4L2 device", path)
                                            : fmt::format("{}: cannot open the {} node: {}", path,
                                                          config_.role, std::strerror(error)));
  }
  opened_ = true;
  v4l2_capability caps{};
  if (const int error = device_->queryCapabilities(caps)) {
    throw core::SourceError(
        fmt::format("{}: not a V4L2 device (VIDIOC_QUERYCAP: {})", path, std::strerror(error)));
  }
  const std::uint32_t node_caps =
      (caps.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? caps.device_caps : caps.capabilities;
  if ((node_caps & V4L2_CAP_VIDEO_CAPTURE) == 0 || (node_caps & V4L2_CAP_STREAMING) == 0) {
    // UVC cameras create a second node per stream for metadata; it is easy to pick by mistake.
    throw core::SourceError(
        fmt::format("{}: not a video capture node with streaming I/O (a metadata node?)", path));
  }
  negotiate();
  startStreaming();
  spdlog::info("{}: {} {} {}x{}, {} buffers", path, config_.role, fourccName(format_.fourcc),
               format_.width, format_.height, buffers_.size());
}

void V4l2Capture::negotiate() {
  const std::string& path = config_.path;
  // ENUM_FMT ends with EINVAL; the bound only guards against a driver that never ends.
  for (std::uint32_t index = 0; index < 256; ++index) {
    v4l2_fmtdesc desc{};
    desc.index = index;
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    const int error = device_->enumerateFormat(desc);
    if (error == EINVAL) break;
    if (error != 0) throw core::SourceError(deviceFailure("VIDIOC_ENUM_FMT", error));
    offered_.push_back(desc.pixelformat);
  }
  const auto wanted = std::find_first_of(config_.formats.begin(), config_.formats.end(),
                                         offered_.begin(), offered_.end());
  if (wanted == config_.formats.end()) {
    throw core::SourceError(fmt::format(
        "{}: the {} node offers none of the formats tessera reads for {} ({}); it offers {}", path,
        config_.role, config_.role, joinNames(config_.formats), joinNames(offered_)));
  }
  const std::uint32_t fourcc = *wanted;

  v4l2_format format{};
  format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (const int error = device_->getFormat(format)) {
    throw core::SourceError(deviceFailure("VIDIOC_G_FMT", error));
  }
  v4l2_pix_format& pix = format.fmt.pix;
  pix.pixelformat = fourcc;
  if (config_.width > 0 && config_.height > 0) {
    pix.width = static_cast<std::uint32_t>(config_.width);
    pix.height = static_cast<std::uint32_t>(config_.height);
  }
  pix.field = V4L2_FIELD_NONE;
  pix.bytesperline = 0;  // the driver fills in the layout for the new format
  pix.sizeimage = 0;
  v4l2_format tried = format;
  const int try_error = device_->tryFormat(tried);
  if (try_error != 0 && try_error != ENOTTY) {  // TRY_FMT is optional for drivers
    throw core::SourceError(deviceFailure("VIDIOC_TRY_FMT", try_error));
  }
  if (try_error == 0 && tried.fmt.pix.pixelformat != fourcc) {
    throw core::SourceError(fmt::format("{}: lists {} but refuses it (it proposes {})", path,
                                        fourccName(fourcc), fourccName(tried.fmt.pix.pixelformat)));
  }
  if (const int error = device_->setFormat(format)) {
    throw core::SourceError(deviceFailure("VIDIOC_S_FMT", error));
  }
  if (pix.pixelformat != fourcc) {
    throw core::SourceError(fmt::format("{}: asked for {}, the node set {}", path,
                                        fourccName(fourcc), fourccName(pix.pixelformat)));
  }
  if (config_.width > 0 && config_.height > 0 &&
      (static_cast<int>(pix.width) != config_.width ||
       static_cast<int>(pix.height) != config_.height)) {
    throw core::SourceError(
        fmt::format("{}: asked for {}x{} {}, the node delivers {}x{}{}", path, config_.width,
                    config_.height, fourccName(fourcc), pix.width, pix.height,
                    config_.size_reason.empty() ? "" : "; " + config_.size_reason));
  }
  format_.fourcc = fourcc;
  format_.width = static_cast<int>(pix.width);
  format_.height = static_cast<int>(pix.height);
  format_.bytes_per_line = pix.bytesperline;
  format_.size_image = pix.sizeimage;
  if (isUncompressed(fourcc)) {
    // Some drivers leave bytesperline 0 for packed formats; some round sizeimage up to a page.
    // A complete frame is what the conversion reads: bytes_per_line x height.
    const auto packed = static_cast<std::uint32_t>(format_.width * bytesPerPixel(fourcc));
    format_.bytes_per_line = std::max(format_.bytes_per_line, packed);
    format_.size_image = format_.bytes_per_line * static_cast<std::uint32_t>(format_.height);
  }
}

void V4l2Capture::startStreaming() {
  v4l2_requestbuffers request{};
  request.count = static_cast<std::uint32_t>(std::max(config_.buffer_count, 1));
  request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  request.memory = V4L2_MEMORY_MMAP;
  if (const int error = device_->requestBuffers(request)) {
    throw core::SourceError(deviceFailure("VIDIOC_REQBUFS (mmap streaming)", error));
  }
  buffers_requested_ = true;
  if (request.count == 0) {
    throw core::SourceError(fmt::format("{}: the node granted no streaming buffers", path()));
  }
  buffers_.resize(request.count);
  for (std::uint32_t index = 0; index < request.count; ++index) {
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = index;
    if (const int error = device_->queryBuffer(buffer)) {
      throw core::SourceError(deviceFailure("VIDIOC_QUERYBUF", error));
    }
    void* start = nullptr;
    if (const int error = device_->map(buffer.m.offset, buffer.length, start)) {
      throw core::SourceError(deviceFailure("mmap", error));
    }
    buffers_[index] = {start, buffer.length};
    if (const int error = device_->queueBuffer(buffer)) {
      throw core::SourceError(deviceFailure("VIDIOC_QBUF", error));
    }
  }
  if (const int error = device_->streamOn()) {
    throw core::SourceError(deviceFailure("VIDIOC_STREAMON", error));
  }
  streaming_ = true;
  last_frame_ = Clock::now();
}

void V4l2Capture::release() {
  // Failures are ignored here: after an unplug every call fails, and there is nothing left
  // to do about it but to let go of the node.
  if (streaming_) device_->streamOff();
  streaming_ = false;
  for (const Buffer& buffer : buffers_) {
    if (buffer.start != nullptr) device_->unmap(buffer.start, buffer.length);
  }
  buffers_.clear();
  if (buffers_requested_) {
    v4l2_requestbuffers none{};
    none.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    none.memory = V4L2_MEMORY_MMAP;
    device_->requestBuffers(none);  // count 0 frees the driver's buffers
    buffers_requested_ = false;
  }
  if (opened_) device_->close();
  opened_ = false;
}

std::string V4l2Capture::deviceFailure(const char* operation, int error) const {
  if (deviceGone(error)) {
    return fmt::format("{}: the {} device disappeared ({}) after {} frames", config_.path,
                       config_.role, std::strerror(error), dequeued_);
  }
  return fmt::format("{}: {} failed on the {} node: {} (after {} frames)", config_.path, operation,
                     config_.role, std::strerror(error), dequeued_);
}

CaptureResult V4l2Capture::end(std::string problem) {
  ended_ = true;
  end_problem_ = std::move(problem);
  CaptureResult result;
  result.problem = end_problem_;
  return result;
}

CaptureResult V4l2Capture::next(int timeout_ms) {
  if (ended_) return end(end_problem_);
  const auto stall = std::chrono::milliseconds(config_.stall_timeout_ms);
  const auto nothing_yet = [&]() {
    if (Clock::now() - last_frame_ < stall)
      return CaptureResult{CaptureStatus::kTimeout, {}, 0, 0, {}};
    return end(fmt::format("{}: the {} stream stalled: no frame for {} ms after {} frames",
                           config_.path, config_.role, config_.stall_timeout_ms, dequeued_));
  };
  const auto stall_left =
      std::chrono::duration_cast<std::chrono::milliseconds>(stall - (Clock::now() - last_frame_));
  const int wait = static_cast<int>(std::clamp<std::int64_t>(
      std::min<std::int64_t>(timeout_ms, stall_left.count()), 0, config_.stall_timeout_ms));
  bool ready = false;
  if (const int error = device_->waitForFrame(wait, ready))
    return end(deviceFailure("poll", error));
  if (!ready) return nothing_yet();

  v4l2_buffer buffer{};
  buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buffer.memory = V4L2_MEMORY_MMAP;
  const int error = device_->dequeueBuffer(buffer);
  if (error == EAGAIN) return nothing_yet();  // poll woke without a full buffer
  if (error != 0) return end(deviceFailure("VIDIOC_DQBUF", error));
  if (buffer.index >= buffers_.size()) {
    return end(fmt::format("{}: the driver returned unknown buffer {}", path(), buffer.index));
  }
  ++dequeued_;
  last_frame_ = Clock::now();

  CaptureResult result;
  result.timestamp_ns = static_cast<std::int64_t>(buffer.timestamp.tv_sec) * 1'000'000'000 +
                        static_cast<std::int64_t>(buffer.timestamp.tv_usec) * 1'000;
  result.sequence = buffer.sequence;
  const Buffer& mapped = buffers_[buffer.index];
  const std::uint32_t used = std::min(buffer.bytesused, mapped.length);
  if ((buffer.flags & V4L2_BUF_FLAG_ERROR) != 0) {
    result.status = CaptureStatus::kBadImage;
    result.problem = fmt::format("{}: the driver flagged {} frame {} as corrupt", path(),
                                 config_.role, buffer.sequence);
  } else if (isUncompressed(format_.fourcc) && used < format_.size_image) {
    result.status = CaptureStatus::kBadImage;
    result.problem = fmt::format("{}: short {} frame {}: {} of {} bytes", path(), config_.role,
                                 buffer.sequence, used, format_.size_image);
  } else {
    result.status = CaptureStatus::kImage;
    result.bytes = cv::Mat(1, static_cast<int>(used), CV_8UC1, mapped.start).clone();
  }
  // Requeue at once: the copy above is ours. If the node is gone now, this frame still counts
  // and the next call reports the end.
  if (const int requeue_error = device_->queueBuffer(buffer)) {
    ended_ = true;
    end_problem_ = deviceFailure("VIDIOC_QBUF", requeue_error);
  }
  return result;
}

}  // namespace tessera::drivers::v4l2
