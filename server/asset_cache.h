// AssetCache: uploaded seeds (meshes, seed volumes) kept in memory, content-addressed, bounded in bytes (LRU).
// Contract:
//   * An Asset is immutable once built and shared by pointer: a query holding one keeps it alive even after
//     the cache evicts it, so eviction never disturbs a running query.
//   * insert() evicts least-recently-used assets until the new one fits; an asset larger than the whole
//     capacity is refused (the caller answers RESOURCE_EXHAUSTED). find() refreshes recency.
//   * Ids are "mesh-<sha256 hex>" / "volume-<sha256 hex>" of the uploaded bytes, so identical uploads share one
//     entry and a client may compute an id itself.
// Thread-safe (one mutex; every operation is O(1) apart from eviction).
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "core/field/band_extent.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/label_volume.h"
#include "core/types.h"

namespace distband {

struct Asset {
  enum class Kind { kMesh, kVolume };
  Kind kind = Kind::kMesh;
  std::string id;
  std::string name;  ///< the uploader's label, for logs
  // kMesh
  std::shared_ptr<const TriangleMesh> mesh;
  MeshReport mesh_report;
  // kVolume: the seed or label volume (nonzero = seed)
  LabelVolume volume;
  std::shared_ptr<const VolumeFootprint> footprint;  ///< seed and boundary voxels (admission estimates)

  uint64_t memoryBytes() const;  ///< what the asset costs the cache
};

/// Lowercase hex SHA-256 of the concatenation of `parts`.
std::string sha256Hex(std::initializer_list<std::string_view> parts);

class AssetCache {
 public:
  explicit AssetCache(uint64_t capacity_bytes) : capacity_(capacity_bytes) {}

  std::shared_ptr<const Asset> find(const std::string& id);
  /// Returns false (and stores nothing) when the asset alone exceeds the capacity.
  bool insert(std::shared_ptr<const Asset> asset);

  uint64_t usedBytes() const;
  uint64_t capacityBytes() const { return capacity_; }
  size_t size() const;

 private:
  struct Entry {
    std::shared_ptr<const Asset> asset;
    uint64_t bytes;
  };
  mutable std::mutex mu_;
  const uint64_t capacity_;
  uint64_t used_ = 0;
  std::list<Entry> lru_;  ///< most recent first
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
};

}  // namespace distband
