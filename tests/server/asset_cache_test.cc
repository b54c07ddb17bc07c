// AssetCache and sha256Hex (server/asset_cache.h): content lookup, LRU eviction by bytes (find() and a repeated
// insert() refresh recency), refusal of an asset larger than the whole capacity (nothing evicted for it), evicted
// assets staying alive for their holders, point-search parts charged to their asset, the SHA-256 known answers (FIPS
// 180-2) and a two-thread smoke test.
#include "server/asset_cache.h"

#include <future>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

/// A volume asset whose mask has `mask_bytes` bytes (what makes its memoryBytes()); ids of one length so that
/// assets with equal masks cost equal bytes.
std::shared_ptr<const Asset> volume(const std::string& id, size_t mask_bytes, uint8_t fill = 1) {
  auto a = std::make_shared<Asset>();
  a->kind = Asset::Kind::kVolume;
  a->id = id;
  a->volume = LabelVolume::ofMask({int32_t(mask_bytes), 1, 1}, std::vector<uint8_t>(mask_bytes, fill));
  return a;
}

constexpr size_t kMask = 1000;
uint64_t unitBytes() { return volume("volume-a", kMask)->memoryBytes(); }

TEST(AssetCacheTest, MemoryBytesCountsTheMaskAndTheId) {
  const uint64_t small = volume("volume-a", 10)->memoryBytes();
  EXPECT_EQ(volume("volume-a", 1010)->memoryBytes(), small + 1000);
  EXPECT_EQ(volume("volume-abc", 10)->memoryBytes(), small + 2);
  EXPECT_GE(small, sizeof(Asset) + 10);
}

TEST(AssetCacheTest, FindsWhatWasInserted) {
  AssetCache cache(10 * unitBytes());
  EXPECT_EQ(cache.find("volume-a"), nullptr);
  auto a = volume("volume-a", kMask);
  ASSERT_TRUE(cache.insert(a));
  EXPECT_EQ(cache.find("volume-a"), a) << "the same shared asset, not a copy";
  EXPECT_EQ(cache.find("volume-b"), nullptr);
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.usedBytes(), a->memoryBytes());
  EXPECT_EQ(cache.capacityBytes(), 10 * unitBytes());
}

TEST(AssetCacheTest, InsertingAnIdAgainKeepsOneEntry) {
  AssetCache cache(10 * unitBytes());
  auto first = volume("volume-a", kMask, 1);
  auto second = volume("volume-a", kMask, 2);
  ASSERT_TRUE(cache.insert(first));
  const uint64_t used = cache.usedBytes();
  EXPECT_TRUE(cache.insert(second)) << "an already cached id is a success";
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.usedBytes(), used) << "bytes are not counted twice";
  EXPECT_EQ(cache.find("volume-a"), first) << "ids are content hashes: the cached asset stays";
}

TEST(AssetCacheTest, EvictsTheLeastRecentlyUsed) {
  const uint64_t unit = unitBytes();
  AssetCache cache(3 * unit);
  for (const char* id : {"volume-a", "volume-b", "volume-c"}) ASSERT_TRUE(cache.insert(volume(id, kMask)));
  EXPECT_EQ(cache.usedBytes(), 3 * unit);
  ASSERT_TRUE(cache.insert(volume("volume-d", kMask)));
  EXPECT_EQ(cache.find("volume-a"), nullptr) << "the oldest is evicted first";
  EXPECT_NE(cache.find("volume-b"), nullptr);
  EXPECT_NE(cache.find("volume-c"), nullptr);
  EXPECT_NE(cache.find("volume-d"), nullptr);
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_EQ(cache.usedBytes(), 3 * unit);
}

TEST(AssetCacheTest, FindRefreshesRecency) {
  AssetCache cache(3 * unitBytes());
  for (const char* id : {"volume-a", "volume-b", "volume-c"}) ASSERT_TRUE(cache.insert(volume(id, kMask)));
  ASSERT_NE(cache.find("volume-a"), nullptr);  // a is now the most recent; b the least
  ASSERT_TRUE(cache.insert(volume("volume-d", kMask)));
  EXPECT_NE(cache.find("volume-a"), nullptr);
  EXPECT_EQ(cache.find("volume-b"), nullptr);
  EXPECT_NE(cache.find("volume-c"), nullptr);
}

TEST(AssetCacheTest, ReinsertRefreshesRecency) {
  AssetCache cache(3 * unitBytes());
  for (const char* id : {"volume-a", "volume-b", "volume-c"}) ASSERT_TRUE(cache.insert(volume(id, kMask)));
  ASSERT_TRUE(cache.insert(volume("volume-a", kMask)));  // the upload of a again
  ASSERT_TRUE(cache.insert(volume("volume-d", kMask)));
  EXPECT_NE(cache.find("volume-a"), nullptr);
  EXPECT_EQ(cache.find("volume-b"), nullptr);
}

TEST(AssetCacheTest, EvictsAsManyAsTheNewAssetNeeds) {
  const uint64_t unit = unitBytes();
  AssetCache cache(3 * unit);
  for (const char* id : {"volume-a", "volume-b", "volume-c"}) ASSERT_TRUE(cache.insert(volume(id, kMask)));
  // Exactly two units (one Asset and id, a mask of unit + kMask bytes): evicting a leaves 2 + 2 > 3 units, so b
  // must go too; then 1 + 2 units fit and c stays.
  auto big = volume("volume-e", kMask + unit);
  ASSERT_EQ(big->memoryBytes(), 2 * unit);
  ASSERT_TRUE(cache.insert(big));
  EXPECT_EQ(cache.find("volume-a"), nullptr);
  EXPECT_EQ(cache.find("volume-b"), nullptr);
  EXPECT_NE(cache.find("volume-c"), nullptr);
  EXPECT_NE(cache.find("volume-e"), nullptr);
  EXPECT_EQ(cache.usedBytes(), unit + big->memoryBytes());
  EXPECT_LE(cache.usedBytes(), cache.capacityBytes());
}

TEST(AssetCacheTest, AssetOfExactlyTheCapacityFitsAlone) {
  const uint64_t unit = unitBytes();
  AssetCache cache(unit);
  ASSERT_TRUE(cache.insert(volume("volume-a", kMask)));
  ASSERT_TRUE(cache.insert(volume("volume-b", kMask)));
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.find("volume-a"), nullptr);
  EXPECT_NE(cache.find("volume-b"), nullptr);
}

TEST(AssetCacheTest, RefusesAnAssetLargerThanTheCapacityWithoutEvicting) {
  const uint64_t unit = unitBytes();
  AssetCache cache(2 * unit);
  ASSERT_TRUE(cache.insert(volume("volume-a", kMask)));
  ASSERT_TRUE(cache.insert(volume("volume-b", kMask)));
  auto huge = volume("volume-h", 2 * unit);
  ASSERT_GT(huge->memoryBytes(), cache.capacityBytes());
  EXPECT_FALSE(cache.insert(huge));
  EXPECT_EQ(cache.find("volume-h"), nullptr);
  EXPECT_EQ(cache.size(), 2u) << "a refused asset must not evict anything";
  EXPECT_NE(cache.find("volume-a"), nullptr);
  EXPECT_NE(cache.find("volume-b"), nullptr);
  EXPECT_EQ(cache.usedBytes(), 2 * unit);
}

TEST(AssetCacheTest, ZeroCapacityStoresNothing) {
  AssetCache cache(0);
  EXPECT_FALSE(cache.insert(volume("volume-a", 1)));
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(cache.usedBytes(), 0u);
}

TEST(AssetCacheTest, EvictedAssetStaysAliveForItsHolder) {
  AssetCache cache(unitBytes());
  ASSERT_TRUE(cache.insert(volume("volume-a", kMask, 7)));
  std::shared_ptr<const Asset> held = cache.find("volume-a");
  ASSERT_TRUE(cache.insert(volume("volume-b", kMask)));
  ASSERT_EQ(cache.find("volume-a"), nullptr);
  ASSERT_NE(held, nullptr);
  EXPECT_EQ(held->id, "volume-a");
  ASSERT_EQ(held->volume.bytes().size(), kMask);
  EXPECT_EQ(held->volume.at(kMask - 1), 7u);
}

TEST(AssetCacheTest, MeshAssetsCostTheirVertices) {
  auto mesh = std::make_shared<TriangleMesh>();
  mesh->vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh->triangles = {{0, 1, 2}};
  Asset a;
  a.kind = Asset::Kind::kMesh;
  a.id = "mesh-x";
  const uint64_t empty = a.memoryBytes();
  a.mesh = mesh;
  EXPECT_EQ(a.memoryBytes(), empty + 3 * sizeof(Vec3d) + sizeof(mesh->triangles[0]));
}

// FIPS 180-2 appendix B known answers.
/// A point search holding a BVH over a small mesh: a part whose memoryBytes() the cache must charge.
PointSearch meshSearch() {
  TriangleMesh mesh;
  for (int i = 0; i < 40; ++i) {
    const uint32_t v = uint32_t(mesh.vertices.size());
    mesh.vertices.push_back({double(i), 0, 0});
    mesh.vertices.push_back({double(i) + 1, 0, 0});
    mesh.vertices.push_back({double(i), 1, 0});
    mesh.triangles.push_back({v, v + 1, v + 2});
  }
  auto bvh = std::make_shared<TriangleBvh>();
  EXPECT_TRUE(TriangleBvh::build(mesh, nullptr, bvh.get()).ok());
  PointSearch search;
  search.mesh = std::move(bvh);
  return search;
}

TEST(AssetCacheTest, KeptSearchPartsAreChargedToTheirAssetAndMakeRoomLikeAnInsert) {
  const PointSearch search = meshSearch();
  const uint64_t part = search.mesh->memoryBytes();
  ASSERT_GT(part, 0u);
  const size_t mask = 2 * part;  // an asset costs more than the part: evicting one makes room for one part
  const uint64_t unit = volume("volume-a", mask)->memoryBytes();
  AssetCache cache(3 * unit + part);
  auto a = volume("volume-a", mask), b = volume("volume-b", mask), c = volume("volume-c", mask);
  ASSERT_TRUE(cache.insert(a) && cache.insert(b) && cache.insert(c));
  cache.find("volume-a");  // b is now the least recently used, then c, then a
  PointPlan plan;
  EXPECT_EQ(a->search_parts->forPlan(plan).mesh, nullptr);
  ASSERT_TRUE(cache.keepSearchParts(a, search));
  EXPECT_EQ(a->search_parts->forPlan(plan).mesh, search.mesh) << "kept: the next plan finds it";
  EXPECT_EQ(cache.usedBytes(), 3 * unit + part) << "fits without evicting";
  EXPECT_TRUE(cache.keepSearchParts(a, search)) << "kept once, charged once";
  EXPECT_EQ(cache.usedBytes(), 3 * unit + part);

  // Another asset's parts make room from the least recently used end: b goes, a (just used) and c stay.
  ASSERT_TRUE(cache.keepSearchParts(c, search));
  EXPECT_EQ(cache.find("volume-b"), nullptr);
  EXPECT_NE(cache.find("volume-a"), nullptr);
  EXPECT_EQ(cache.usedBytes(), 2 * unit + 2 * part);
  // An asset leaves with its parts and their bytes: a new asset evicts c (the least recently used) and its part.
  ASSERT_TRUE(cache.insert(volume("volume-d", mask)));
  EXPECT_EQ(cache.find("volume-c"), nullptr);
  EXPECT_EQ(cache.usedBytes(), 2 * unit + part);
}

TEST(AssetCacheTest, SearchPartsOfAnAssetNotCachedOrTooLargeAreNotKept) {
  const PointSearch search = meshSearch();
  const uint64_t part = search.mesh->memoryBytes();
  AssetCache cache(unitBytes() + part - 1);
  auto a = volume("volume-a", kMask);
  ASSERT_TRUE(cache.insert(a));
  EXPECT_FALSE(cache.keepSearchParts(a, search)) << "the asset and its parts exceed the capacity";
  EXPECT_EQ(a->search_parts->forPlan(PointPlan{}).mesh, nullptr);
  EXPECT_EQ(cache.usedBytes(), unitBytes());
  EXPECT_NE(cache.find("volume-a"), nullptr) << "nothing evicted for a refusal";
  auto inline_asset = volume("volume-a", kMask);  // the same id, but not the cache's object (an inline upload)
  EXPECT_FALSE(cache.keepSearchParts(inline_asset, search));
  auto never = volume("volume-z", kMask);
  EXPECT_FALSE(cache.keepSearchParts(never, search));
  EXPECT_EQ(cache.usedBytes(), unitBytes());
}

TEST(Sha256HexTest, KnownAnswers) {
  EXPECT_EQ(sha256Hex({"abc"}), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256Hex({""}), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(sha256Hex({}), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(sha256Hex({"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"}),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(sha256Hex({std::string(1000000, 'a')}),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(Sha256HexTest, HashesTheConcatenationOfItsParts) {
  EXPECT_EQ(sha256Hex({"a", "", "bc"}), sha256Hex({"abc"}));
  EXPECT_NE(sha256Hex({"ab", "c"}), sha256Hex({"abd"}));
}

TEST(Sha256HexTest, BytesAreHashedVerbatimIncludingZeros) {
  const std::string with_nul("a\0b", 3);
  EXPECT_NE(sha256Hex({with_nul}), sha256Hex({"a"}));
  EXPECT_NE(sha256Hex({with_nul}), sha256Hex({"ab"}));
  const std::string hex = sha256Hex({with_nul});
  EXPECT_EQ(hex.size(), 64u);
  EXPECT_EQ(hex.find_first_not_of("0123456789abcdef"), std::string::npos) << "lowercase hex";
}

TEST(AssetCacheTest, TwoThreadsInsertingAndFinding) {
  const uint64_t unit = unitBytes();
  AssetCache cache(8 * unit);
  auto worker = [&](char tag) {
    int found = 0;
    for (int i = 0; i < 300; ++i) {
      const std::string id = std::string("volume-") + tag + std::to_string(i % 40);
      if (auto a = cache.find(id)) {
        EXPECT_EQ(a->id, id);
        ++found;
      } else {
        EXPECT_TRUE(cache.insert(volume(id, kMask)));
      }
      EXPECT_LE(cache.usedBytes(), cache.capacityBytes());
    }
    return found;
  };
  auto t1 = std::async(std::launch::async, worker, 'p');
  auto t2 = std::async(std::launch::async, worker, 'q');
  t1.get();
  t2.get();
  EXPECT_LE(cache.size(), 8u);
  EXPECT_GE(cache.size(), 1u);
  // Every id the workers used is looked up: the bytes of those still cached must add up to usedBytes().
  uint64_t expected = 0;
  for (char tag : {'p', 'q'})
    for (int i = 0; i < 40; ++i) {
      const std::string id = std::string("volume-") + tag + std::to_string(i);
      if (auto a = cache.find(id)) expected += a->memoryBytes();
    }
  EXPECT_EQ(cache.usedBytes(), expected) << "usedBytes must equal the sum of the cached assets' bytes";
}

}  // namespace
}  // namespace distband
