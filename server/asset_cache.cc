#include "server/asset_cache.h"

#include <openssl/evp.h>

#include <fmt/format.h>

namespace distband {

uint64_t Asset::memoryBytes() const {
  uint64_t bytes = sizeof(Asset) + id.size() + name.size();
  if (mesh) bytes += mesh->vertices.size() * sizeof(Vec3d) + mesh->triangles.size() * sizeof(mesh->triangles[0]);
  if (volume) bytes += volume.bytes().size();
  if (footprint) bytes += footprint->memoryBytes();
  return bytes;
}

std::string sha256Hex(std::initializer_list<std::string_view> parts) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr);
  for (std::string_view p : parts) EVP_DigestUpdate(ctx, p.data(), p.size());
  EVP_DigestFinal_ex(ctx, digest, &len);
  EVP_MD_CTX_free(ctx);
  std::string hex;
  hex.reserve(len * 2);
  for (unsigned i = 0; i < len; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

std::shared_ptr<const Asset> AssetCache::find(const std::string& id) {
  std::lock_guard lock(mu_);
  auto it = index_.find(id);
  if (it == index_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  return it->second->asset;
}

bool AssetCache::insert(std::shared_ptr<const Asset> asset) {
  const uint64_t bytes = asset->memoryBytes();
  if (bytes > capacity_) return false;
  std::lock_guard lock(mu_);
  if (auto it = index_.find(asset->id); it != index_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second);
    return true;
  }
  makeRoom(bytes, lru_.end());
  lru_.push_front({std::move(asset), bytes});
  index_[lru_.front().asset->id] = lru_.begin();
  used_ += bytes;
  return true;
}

void AssetCache::makeRoom(uint64_t bytes, std::list<Entry>::iterator keep) {
  auto victim = lru_.end();
  while (used_ + bytes > capacity_ && victim != lru_.begin()) {
    --victim;
    if (victim == keep) continue;
    used_ -= victim->bytes;
    index_.erase(victim->asset->id);
    victim = lru_.erase(victim);
  }
}

bool AssetCache::keepSearchParts(const std::shared_ptr<const Asset>& asset, const PointSearch& search) {
  std::lock_guard lock(mu_);
  auto it = index_.find(asset->id);
  if (it == index_.end() || it->second->asset != asset) return false;
  const uint64_t bytes = asset->search_parts->bytesToKeep(search);
  if (bytes == 0) return true;
  if (it->second->bytes + bytes > capacity_) return false;
  makeRoom(bytes, it->second);  // never evicting the asset the parts belong to
  asset->search_parts->keep(search);
  it->second->bytes += bytes;
  used_ += bytes;
  return true;
}

std::shared_ptr<const MeshSign> AssetSearchParts::keptSign(SignMethod method) const {
  for (const auto& kept : signs_)
    if (kept->method() == method) return kept;
  return nullptr;
}

PointSearch AssetSearchParts::forPlan(const PointPlan& plan) const {
  std::lock_guard lock(mu_);
  PointSearch s;
  s.seeds = plan.seeds;
  if (plan.seeds == SeedKind::kMesh) {
    s.mesh = mesh_;
    if (plan.mesh_sign != SignMethod::kUnsigned) s.sign = keptSign(plan.mesh_sign);
    if (plan.farSign() != SignMethod::kUnsigned) s.far_sign = keptSign(plan.farSign());
  } else if (plan.seeds == SeedKind::kVolume) {
    s.volume = volume_[volumeSlot(plan.inside_negative)];
  }
  return s;
}

uint64_t AssetSearchParts::bytesToKeep(const PointSearch& search) const {
  std::lock_guard lock(mu_);
  uint64_t bytes = 0;
  if (search.mesh && !mesh_) bytes += search.mesh->memoryBytes();
  if (search.sign && !keptSign(search.sign->method())) bytes += search.sign->memoryBytes();
  if (search.far_sign && !keptSign(search.far_sign->method()) &&
      !(search.sign && search.sign->method() == search.far_sign->method()))
    bytes += search.far_sign->memoryBytes();
  if (search.volume && !volume_[volumeSlot(search.volume->insideNegative())]) bytes += search.volume->memoryBytes();
  return bytes;
}

void AssetSearchParts::keep(const PointSearch& search) {
  std::lock_guard lock(mu_);
  if (search.mesh && !mesh_) mesh_ = search.mesh;
  for (const auto& sign : {search.sign, search.far_sign})
    if (sign && !keptSign(sign->method())) signs_.push_back(sign);
  if (search.volume) {
    auto& slot = volume_[volumeSlot(search.volume->insideNegative())];
    if (!slot) slot = search.volume;
  }
}

uint64_t AssetCache::usedBytes() const {
  std::lock_guard lock(mu_);
  return used_;
}

size_t AssetCache::size() const {
  std::lock_guard lock(mu_);
  return lru_.size();
}

}  // namespace distband
