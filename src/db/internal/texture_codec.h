#pragma once
// The byte formats of a texture's blob columns. They are tessera's own and versioned by the
// schema (kSchemaVersion): changing one means a new schema version.
//   png         lossless RGBA PNG, alpha = mask
//   ccv         float32 values, little-endian
//   keypoints   u8 format (1), u32 count, then per keypoint: f32 x, y, size, angle, response,
//               i32 octave, class_id (little-endian)
//   descriptors i32 rows, cols, OpenCV type, then rows x cols elements, row-major
// The decoders throw core::Error with a short reason when the bytes do not fit the format.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "tessera/db/texture_record.h"

namespace tessera::db::internal {

using Bytes = std::vector<std::uint8_t>;

// The kind column: "single" or "pattern" (kindName's inverse).
TextureKind parseKind(const std::string& text);

// `rgb` CV_8UC3 in R G B order; `mask` CV_8UC1 of the same size, or empty (all valid).
Bytes encodePng(const cv::Mat& rgb, const cv::Mat& mask);
void decodePng(const void* data, std::size_t bytes, cv::Mat& rgb, cv::Mat& mask);

Bytes encodeFloats(const std::vector<float>& values);
std::vector<float> decodeFloats(const void* data, std::size_t bytes);

Bytes encodeKeypoints(const std::vector<cv::KeyPoint>& keypoints);  // empty for none
std::vector<cv::KeyPoint> decodeKeypoints(const void* data, std::size_t bytes);

Bytes encodeDescriptors(const cv::Mat& descriptors);  // empty for none
cv::Mat decodeDescriptors(const void* data, std::size_t bytes);

}  // namespace tessera::db::internal
