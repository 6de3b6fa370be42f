#pragma once
// Small helpers for the figures' JSON (stage_figures.cpp, map_monitor.cpp).
#include <cstddef>
#include <optional>

#include <nlohmann/json.hpp>

namespace tessera::pipeline::internal {

inline nlohmann::json orNull(const std::optional<double>& value) {
  return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
}

// numerator / denominator; nothing when the denominator is 0.
inline std::optional<double> ratio(std::size_t numerator, std::size_t denominator) {
  if (denominator == 0) return std::nullopt;
  return static_cast<double>(numerator) / static_cast<double>(denominator);
}

}  // namespace tessera::pipeline::internal
