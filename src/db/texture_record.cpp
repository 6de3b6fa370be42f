#include "tessera/db/texture_record.h"

#include <cstdint>

namespace tessera::db {

namespace {

// 64-bit FNV-1a (Fowler, Noll, Vo): not cryptographic, but fast, stable across platforms and
// builds, and ample to tell textures apart within one database.
class Fnv1a64 {
 public:
  void add(const std::uint8_t* data, std::size_t bytes) {
    for (std::size_t i = 0; i < bytes; ++i) {
      hash_ ^= data[i];
      hash_ *= kPrime;
    }
  }
  void addInt(std::int32_t value) {
    // Little-endian byte order whatever the host, so keys match across machines.
    const auto bits = static_cast<std::uint32_t>(value);
    const std::uint8_t bytes[] = {
        static_cast<std::uint8_t>(bits), static_cast<std::uint8_t>(bits >> 8),
        static_cast<std::uint8_t>(bits >> 16), static_cast<std::uint8_t>(bits >> 24)};
    add(bytes, sizeof(bytes));
  }
  void addMatRows(const cv::Mat& mat) {
    const std::size_t row_bytes = static_cast<std::size_t>(mat.cols) * mat.elemSize();
    for (int r = 0; r < mat.rows; ++r) add(mat.ptr<std::uint8_t>(r), row_bytes);
  }
  std::uint64_t value() const { return hash_; }

 private:
  static constexpr std::uint64_t kPrime = 1099511628211ULL;
  std::uint64_t hash_ = 14695981039346656037ULL;  // the offset basis
};

}  // namespace

const char* kindName(TextureKind kind) {
  switch (kind) {
    case TextureKind::kSingle:
      return "single";
    case TextureKind::kPattern:
      return "pattern";
  }
  return "single";
}

std::string contentKey(const cv::Mat& rgb, const cv::Mat& mask) {
  Fnv1a64 fnv;
  fnv.addInt(rgb.cols);
  fnv.addInt(rgb.rows);
  fnv.addInt(rgb.type());
  fnv.addMatRows(rgb);
  if (mask.empty()) {
    // No mask means every texel is valid; hashing it as all 255 keeps the key equal to that of
    // the same image stored with an explicit full mask (which is what the store reads back).
    const std::uint8_t valid = 255;
    for (std::size_t i = 0; i < rgb.total(); ++i) fnv.add(&valid, 1);
  } else {
    fnv.addMatRows(mask);
  }
  std::uint64_t hash = fnv.value();
  std::string hex(16, '0');
  for (int i = 15; i >= 0; --i, hash >>= 4)
    hex[static_cast<std::size_t>(i)] = "0123456789abcdef"[hash & 0xf];
  return hex;
}

}  // namespace tessera::db
