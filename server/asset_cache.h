// AssetCache: uploaded seeds (meshes, seed volumes) kept in memory, content-addressed, bounded in bytes (LRU).
// Contract:
//   * An Asset is immutable once built and shared by pointer: a query holding one keeps it alive even after
//     the cache evicts it, so eviction never disturbs a running query.
//   * insert() evicts least-recently-used assets until the new one fits; an asset larger than the whole
//     capacity is refused (the caller answers RESOURCE_EXHAUSTED). find() refreshes recency.
//   * Ids are "mesh-<sha256 hex>" / "volume-<sha256 hex>" of the uploaded bytes, so identical uploads share one
//     entry and a client may compute an id itself.
//   * A cached asset also keeps the point-query search parts built for it (a BVH, mesh signs, a volume search), so
//     that only the first QueryPoints on it builds them. keepSearchParts() charges their bytes to the asset's entry,
//     evicting other assets as insert() does, and keeps nothing when they cannot fit; they go with the asset.
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
#include "core/points/point_plan.h"
#include "core/points/point_query.h"
#include "core/seeds/label_volume.h"
#include "core/types.h"

namespace distband {

/// The point-query search parts kept with a cached asset (see the contract above). Thread-safe.
class AssetSearchParts {
 public:
  /// The kept parts that `plan` can use; null where none is kept.
  PointSearch forPlan(const PointPlan& plan) const;
  /// The bytes the parts of `search` not yet kept would add.
  uint64_t bytesToKeep(const PointSearch& search) const;
  /// Keeps the parts of `search` not yet kept.
  void keep(const PointSearch& search);

 private:
  static int volumeSlot(bool inside_negative) { return inside_negative ? 1 : 0; }
  std::shared_ptr<const MeshSign> keptSign(SignMethod method) const;  ///< mu_ held
  mutable std::mutex mu_;
  std::shared_ptr<const TriangleBvh> mesh_;
  std::vector<std::shared_ptr<const MeshSign>> signs_;  ///< at most one per sign method
  std::shared_ptr<const VolumeSearch> volume_[2];       ///< by insideNegative()
};

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
  /// Point-query search parts, kept while the asset is cached (AssetCache::keepSearchParts charges them).
  std::shared_ptr<AssetSearchParts> search_parts = std::make_shared<AssetSearchParts>();

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
  /// Keeps the parts of `search` that `asset` (this cache's entry, not an inline asset) does not hold yet, charging
  /// their bytes to its entry. Returns false, keeping nothing, when the asset is no longer cached or the parts do not
  /// fit beside it.
  bool keepSearchParts(const std::shared_ptr<const Asset>& asset, const PointSearch& search);

  uint64_t usedBytes() const;
  uint64_t capacityBytes() const { return capacity_; }
  size_t size() const;

 private:
  struct Entry {
    std::shared_ptr<const Asset> asset;
    uint64_t bytes;
  };
  /// Evicts from the least recently used end, never `keep`, until `bytes` more fit or nothing else is left. mu_ held.
  void makeRoom(uint64_t bytes, std::list<Entry>::iterator keep);

  mutable std::mutex mu_;
  const uint64_t capacity_;
  uint64_t used_ = 0;
  std::list<Entry> lru_;  ///< most recent first
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
};

}  // namespace distband
