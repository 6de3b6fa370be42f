// The real backend of V4l2Device: libv4l2 on a /dev/videoN node.
#include <cerrno>
#include <cstdio>

#include <fcntl.h>
#include <poll.h>
#include <sys/mman.h>

#include <libv4l2.h>

#include "tessera/drivers/v4l2/v4l2_device.h"

namespace tessera::drivers::v4l2 {

namespace {

class SystemDevice : public V4l2Device {
 public:
  ~SystemDevice() override { close(); }

  int open(const std::string& path) override {
    close();
    // Non-blocking: a dequeue with no full buffer returns EAGAIN; waiting is poll()'s job,
    // so that a stalled device cannot hang the reader.
    fd_ = v4l2_open(path.c_str(), O_RDWR | O_NONBLOCK);
    return fd_ < 0 ? errno : 0;
  }

  void close() override {
    if (fd_ >= 0) v4l2_close(fd_);
    fd_ = -1;
  }

  int queryCapabilities(v4l2_capability& caps) override { return call(VIDIOC_QUERYCAP, &caps); }
  int enumerateFormat(v4l2_fmtdesc& desc) override { return call(VIDIOC_ENUM_FMT, &desc); }
  int getFormat(v4l2_format& format) override { return call(VIDIOC_G_FMT, &format); }
  int tryFormat(v4l2_format& format) override { return call(VIDIOC_TRY_FMT, &format); }
  int setFormat(v4l2_format& format) override { return call(VIDIOC_S_FMT, &format); }
  int requestBuffers(v4l2_requestbuffers& request) override {
    return call(VIDIOC_REQBUFS, &request);
  }
  int queryBuffer(v4l2_buffer& buffer) override { return call(VIDIOC_QUERYBUF, &buffer); }

  int map(std::uint32_t offset, std::uint32_t length, void*& start) override {
    start = v4l2_mmap(nullptr, length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_,
                      static_cast<std::int64_t>(offset));
    if (start == MAP_FAILED) {
      start = nullptr;
      return errno;
    }
    return 0;
  }

  int unmap(void* start, std::uint32_t length) override {
    return v4l2_munmap(start, length) < 0 ? errno : 0;
  }

  int queueBuffer(v4l2_buffer& buffer) override { return call(VIDIOC_QBUF, &buffer); }
  int dequeueBuffer(v4l2_buffer& buffer) override { return call(VIDIOC_DQBUF, &buffer); }

  int streamOn() override {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    return call(VIDIOC_STREAMON, &type);
  }

  int streamOff() override {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    return call(VIDIOC_STREAMOFF, &type);
  }

  int waitForFrame(int timeout_ms, bool& ready) override {
    pollfd entry{fd_, POLLIN, 0};
    const int n = ::poll(&entry, 1, timeout_ms);
    if (n < 0) {
      ready = false;
      return errno == EINTR ? 0 : errno;  // a signal is an early timeout, not a failure
    }
    // POLLERR/POLLHUP (e.g. an unplugged camera) also count: the dequeue names the errno.
    ready = n > 0;
    return 0;
  }

 private:
  // The ioctl, retried when a signal interrupts it.
  int call(unsigned long request, void* argument) {
    int result = 0;
    do {
      result = v4l2_ioctl(fd_, request, argument);
    } while (result < 0 && errno == EINTR);
    return result < 0 ? errno : 0;
  }

  int fd_ = -1;
};

}  // namespace

std::unique_ptr<V4l2Device> makeSystemDevice() { return std::make_unique<SystemDevice>(); }

std::string fourccName(std::uint32_t fourcc) {
  std::string name;
  for (int shift = 0; shift < 32; shift += 8) {
    const char c = static_cast<char>((fourcc >> shift) & 0x7f);
    if (c < 0x20 || c > 0x7e) {
      char hex[16];
      std::snprintf(hex, sizeof hex, "0x%08x", fourcc);
      return hex;
    }
    name += c;
  }
  while (!name.empty() && name.back() == ' ') name.pop_back();  // "Z16 " -> "Z16"
  if ((fourcc & (1u << 31)) != 0) name += "-BE";                // big-endian variant
  return name;
}

}  // namespace tessera::drivers::v4l2
