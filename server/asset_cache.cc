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
  while (used_ + bytes > capacity_ && !lru_.empty()) {
    used_ -= lru_.back().bytes;
    index_.erase(lru_.back().asset->id);
    lru_.pop_back();
  }
  lru_.push_front({std::move(asset), bytes});
  index_[lru_.front().asset->id] = lru_.begin();
  used_ += bytes;
  return true;
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
