// Shared body of the point-cloud fuzz targets: readPointCloud on arbitrary bytes with a small limit. An accepted cloud
// must hold finite points within the limit, and reading it again a few points at a time must give the same points —
// from memory, and from a file through the smallest read block (the refills a real file needs); a refusal must be
// kInvalidArgument or kResourceExhausted and name the input, and the file path must refuse it too.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/io/point_cloud.h"

/// Reads `bytes` as a file (an in-memory one: no disk traffic per input) `points_per_call` points at a time through a
/// 64-byte block; false when the reader refuses it.
inline bool readThroughAFile(std::string_view bytes, distband::PointFileFormat format, distband::PointReadLimits limits,
                             std::vector<distband::Vec3d>* out) {
  static const int fd = memfd_create("point_cloud_fuzz", 0);
  if (fd < 0 || ftruncate(fd, 0) != 0) __builtin_trap();
  if (!bytes.empty() && pwrite(fd, bytes.data(), bytes.size(), 0) != ssize_t(bytes.size())) __builtin_trap();
  limits.block_bytes = 64;
  std::unique_ptr<distband::PointCloudReader> reader;
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  if (!distband::PointCloudReader::fromFile(path, format, limits, &reader).ok()) return false;
  for (;;) {
    const size_t before = out->size();
    if (!reader->next(5, out).ok()) return false;
    if (out->size() == before) return true;
  }
}

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
    std::vector<distband::Vec3d> from_file;
    if (readThroughAFile(bytes, format, limits, &from_file)) __builtin_trap();
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
  std::vector<distband::Vec3d> from_file;
  if (!readThroughAFile(bytes, format, limits, &from_file) || from_file != points) __builtin_trap();
  return 0;
}
