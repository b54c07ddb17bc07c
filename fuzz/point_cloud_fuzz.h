// Shared body of the point-cloud fuzz targets: readPointCloud on arbitrary bytes with a small limit. An accepted cloud
// must hold finite points within the limit, and reading it again a few points at a time must give the same points; a
// refusal must be kInvalidArgument or kResourceExhausted and name the input.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/io/point_cloud.h"

inline int fuzzPointCloud(distband::PointFileFormat format, const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  distband::PointReadLimits limits;
  limits.max_points = 1 << 16;
  std::vector<distband::Vec3d> points;
  const distband::Status s = distband::readPointCloud(bytes, format, limits, "fuzz", nullptr, &points);
  if (!s.ok()) {
    using Code = distband::Status::Code;
    if (s.code() != Code::kInvalidArgument && s.code() != Code::kResourceExhausted) __builtin_trap();
    if (s.message().find("fuzz") == std::string::npos) __builtin_trap();
    return 0;
  }
  if (points.size() > limits.max_points) __builtin_trap();
  for (const auto& p : points)
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) __builtin_trap();
  std::unique_ptr<distband::PointCloudReader> reader;
  if (!distband::PointCloudReader::fromBytes(bytes, format, limits, "fuzz", &reader).ok()) __builtin_trap();
  std::vector<distband::Vec3d> chunked;
  for (;;) {
    const size_t before = chunked.size();
    if (!reader->next(3, &chunked).ok()) __builtin_trap();
    if (chunked.size() == before) break;
  }
  if (chunked != points) __builtin_trap();
  if (reader->declaredCount() && *reader->declaredCount() != points.size()) __builtin_trap();
  return 0;
}
