// OpenNI's "16zT" lossless depth codec, written from the format description in docs/ONI.md:
// a table of the frame's distinct values, then the table indices as a stream of tokens:
//   byte 0x00-0xDF  two 4-bit deltas (prev - cur + 6), low nibble 0xD = none, 0xF = escape
//   byte 0xE1-0xEF  (b - 0xE0) pairs of zero deltas
//   byte 0xFF       escape: next byte >= 0x80 is a delta (prev - cur + 192),
//                   else it and the following byte are the big-endian absolute value.
#include <algorithm>
#include <cstdlib>

#include <fmt/format.h>

#include "tessera/core/error.h"
#include "tessera/drivers/oni/oni_writer.h"

namespace tessera::drivers::oni {

namespace {

void appendU16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFF));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}

class TokenStream {
 public:
  explicit TokenStream(std::vector<std::uint8_t>& out) : out_(out) {}

  void next(int prev, int cur) {
    const int delta = prev - cur;
    if (std::abs(delta) <= 6) {
      const auto nibble = static_cast<std::uint8_t>(delta + 6);
      if (!half_) {
        pending_ = static_cast<std::uint8_t>(nibble << 4);
        half_ = true;
        return;
      }
      const auto byte = static_cast<std::uint8_t>(pending_ | nibble);
      half_ = false;
      if (byte == 0x66) {  // two zero deltas: counted into a run
        if (++zero_pairs_ == 15) flushZeroRun();
        return;
      }
      flushZeroRun();
      out_.push_back(byte);
      return;
    }
    flushZeroRun();
    out_.push_back(half_ ? static_cast<std::uint8_t>(pending_ | 0x0F) : std::uint8_t{0xFF});
    half_ = false;
    if (std::abs(delta) <= 63) {
      out_.push_back(static_cast<std::uint8_t>(delta + 192));
    } else {
      out_.push_back(static_cast<std::uint8_t>(cur >> 8));  // < 0x80: cur < 32768 (checked)
      out_.push_back(static_cast<std::uint8_t>(cur & 0xFF));
    }
  }

  // The pending zero run precedes the half-filled byte in pixel order, so it is written first.
  void finish() {
    flushZeroRun();
    if (half_) out_.push_back(static_cast<std::uint8_t>(pending_ | 0x0D));
    half_ = false;
  }

 private:
  void flushZeroRun() {
    if (zero_pairs_ > 0) out_.push_back(static_cast<std::uint8_t>(0xE0 + zero_pairs_));
    zero_pairs_ = 0;
  }

  std::vector<std::uint8_t>& out_;
  bool half_ = false;
  std::uint8_t pending_ = 0;
  int zero_pairs_ = 0;
};

}  // namespace

std::vector<std::uint8_t> encode16zT(const cv::Mat& depth_mm) {
  CV_Assert(depth_mm.type() == CV_16UC1 && depth_mm.isContinuous() && !depth_mm.empty());
  const auto* pixels = depth_mm.ptr<std::uint16_t>();
  const std::size_t count = depth_mm.total();

  std::vector<std::uint16_t> table(pixels, pixels + count);
  std::sort(table.begin(), table.end());
  table.erase(std::unique(table.begin(), table.end()), table.end());
  if (table.size() > 32768) {
    throw core::Error(
        fmt::format("16zT: a frame with {} distinct depth values cannot be coded", table.size()));
  }
  std::vector<std::uint16_t> index_of(65536, 0);
  for (std::size_t i = 0; i < table.size(); ++i) index_of[table[i]] = static_cast<std::uint16_t>(i);

  std::vector<std::uint8_t> out;
  out.reserve(count / 2);
  appendU16(out, static_cast<std::uint16_t>(table.size()));
  for (std::uint16_t value : table) appendU16(out, value);
  int prev = index_of[pixels[0]];
  appendU16(out, static_cast<std::uint16_t>(prev));
  TokenStream tokens(out);
  for (std::size_t i = 1; i < count; ++i) {
    const int cur = index_of[pixels[i]];
    tokens.next(prev, cur);
    prev = cur;
  }
  tokens.finish();
  return out;
}

}  // namespace tessera::drivers::oni
