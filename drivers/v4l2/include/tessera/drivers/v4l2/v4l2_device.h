#pragma once
// The seam between capture and the kernel: the few ioctl-level operations streaming capture
// needs from one /dev/videoN node. The system backend forwards them to libv4l2; tests put a
// camera simulated in memory behind the same interface.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <linux/videodev2.h>

namespace tessera::drivers::v4l2 {

// Every operation returns 0 on success or the errno value the call failed with (ENODEV when
// the device is gone, EINVAL for a request it does not support, ...), never -1, so a fake
// can produce any failure the kernel can. Not thread-safe: one capture owns one device.
class V4l2Device {
 public:
  virtual ~V4l2Device() = default;

  virtual int open(const std::string& path) = 0;
  virtual void close() = 0;

  virtual int queryCapabilities(v4l2_capability& caps) = 0;  // VIDIOC_QUERYCAP
  // VIDIOC_ENUM_FMT for desc.index; EINVAL past the last format.
  virtual int enumerateFormat(v4l2_fmtdesc& desc) = 0;
  virtual int getFormat(v4l2_format& format) = 0;                // VIDIOC_G_FMT
  virtual int tryFormat(v4l2_format& format) = 0;                // VIDIOC_TRY_FMT
  virtual int setFormat(v4l2_format& format) = 0;                // VIDIOC_S_FMT
  virtual int requestBuffers(v4l2_requestbuffers& request) = 0;  // VIDIOC_REQBUFS
  virtual int queryBuffer(v4l2_buffer& buffer) = 0;              // VIDIOC_QUERYBUF
  // mmap of a buffer (offset and length as VIDIOC_QUERYBUF gave them), read-only use.
  virtual int map(std::uint32_t offset, std::uint32_t length, void*& start) = 0;
  virtual int unmap(void* start, std::uint32_t length) = 0;
  virtual int queueBuffer(v4l2_buffer& buffer) = 0;    // VIDIOC_QBUF
  virtual int dequeueBuffer(v4l2_buffer& buffer) = 0;  // VIDIOC_DQBUF; EAGAIN when none is full
  virtual int streamOn() = 0;                          // VIDIOC_STREAMON
  virtual int streamOff() = 0;                         // VIDIOC_STREAMOFF
  // poll(): waits up to timeout_ms for a full buffer. Returns 0 with `ready` false on a timeout.
  // An error condition on the node counts as ready, so that the dequeue reports its errno.
  virtual int waitForFrame(int timeout_ms, bool& ready) = 0;
};

// Makes the device object for a node path (the path is passed to open() afterwards too).
using DeviceFactory = std::function<std::unique_ptr<V4l2Device>(const std::string& path)>;

// The real backend: libv4l2's v4l2_open/v4l2_ioctl/v4l2_mmap, which also offers emulated
// formats (e.g. RGB24 from a camera's native Bayer) for devices that need them.
std::unique_ptr<V4l2Device> makeSystemDevice();

// "Z16 ", "YUYV", "MJPG": the four characters of a V4L2 pixel format, for messages.
std::string fourccName(std::uint32_t fourcc);

}  // namespace tessera::drivers::v4l2
