#include "core/band/internal/propagation.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <optional>
#include <type_traits>
#include <utility>
#include <stdexcept>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/first_touch.h"

namespace distband::band_internal {

namespace {
// offer(), inlined into the push (a call and its seven arguments were ~15 % of an offer's instructions).
[[gnu::always_inline]] inline bool offerInline(BandState& s, BrickState* b, uint32_t bi, int off, uint64_t newkey, bool propagates,
                        ThreadBuffers& tb) {
  uint64_t k = b->key[off].load(std::memory_order_relaxed);
  while (newkey < k) {
    if (b->key[off].compare_exchange_weak(k, newkey, std::memory_order_relaxed)) {
      ++tb.updates;
      if (k == kUntouched) {
        if (s.lifespan.enabled) b->expiry[off].store(s.expiryFor(keyDist2(newkey)), std::memory_order_relaxed);
        if (!b->pending.load(std::memory_order_relaxed) && !b->pending.exchange(true)) tb.pending.push_back(bi);
      }
      if (s.collect_dirty && !b->dirty.test(off) && b->dirty.set(off)) tb.dirty.push_back({bi, uint16_t(off)});
      // Listed once per step. Two threads lowering the same voxel at once may both list it: the duplicate
      // offers the same snapshot site twice, which changes nothing.
      if (propagates && !b->listed.test(off) && b->listed.set(off)) {
        tb.next.push_back({bi, uint16_t(off), 0, 0});
      }
      return true;
    }
  }
  return false;
}
}  // namespace

bool offer(BandState& s, BrickState* b, uint32_t bi, int off, uint64_t newkey, bool propagates, ThreadBuffers& tb) {
  return offerInline(s, b, bi, off, newkey, propagates, tb);
}

namespace {

// The push's stand-ins for missing neighbouring bricks (never written): one not created yet, all voxels untouched,
// and one beyond the grid, all voxels marked exact.
struct OutsideBrick : BrickState {
  OutsideBrick() : BrickState({0, 0, 0}, false) {
    for (auto& w : exact.words) w.store(~uint64_t(0), std::memory_order_relaxed);
  }
};
BrickState absent_brick({0, 0, 0}, false);
OutsideBrick outside_brick;

// A triangle site prepared for pushes: its distance test and its plane. The neighbours one push changed follow each
// other in the next front, and a brick's band voxels share triangles, so consecutive pushes mostly offer the same
// site: each loop of pushes keeps the last one (at 256^3, hw 3 and 20: 59-66 % of the pushes reuse it for the
// bunny, 42-47 % for the fandisk, 24-37 % for the armadillo).
struct TrianglePrep {
  uint32_t site = kNoSiteKey;
  TriangleDistance tri{{}, {}, {}};
  Vec3d plane_point{}, unit_normal{};
  const TrianglePrep& of(const Seeds& seeds, uint32_t s) {
    if (s != site) {
      const auto& t = seeds.triangles[s];
      tri = TriangleDistance(t[0], t[1], t[2]);
      const Vec3d n = (t[1] - t[0]).cross(t[2] - t[0]);
      const double len2 = n.lengthSqr();
      plane_point = t[0];
      unit_normal = len2 > 0 ? n * (1.0 / std::sqrt(len2)) : Vec3d{};  // degenerate: bound 0, never rejects
      site = s;
    }
    return *this;
  }
};

template <bool kPoints, bool kExactBand, bool kScaled>
void pushFromT(BandState& s, const FrontEntry& e, ThreadBuffers& tb, TrianglePrep& prep) {
  // Members copied to locals: the atomics and buffer writes below would otherwise force reloads every link.
  BrickTable& table = s.table;
  std::atomic<BrickState*>* const pslot = &table.slot(e.brick);
  BrickState* const pb = pslot->load(std::memory_order_relaxed);
  const Coord l = brickLocal(e.offset);
  const Coord p = pb->origin + l;
  const uint32_t site = e.site;
  const uint8_t* const region_map = s.region;
  const uint8_t region = s.regionOf(p);
  const Coord dims = s.dims;
  const uint32_t dx = uint32_t(dims.x), dy = uint32_t(dims.y), dz = uint32_t(dims.z);
  const float admit2 = s.admit2, frozen2 = s.frozen2;
  const bool lifespan = s.lifespan.enabled, defer = s.defer;
  const int step = s.step;
  const int psum = p.x + p.y + p.z;
  // Point sites: the offset from the site to p, so a neighbour's squared distance is three multiply-adds.
  Vec3d rel{};
  const Vec3d psd = s.metric.unitsOf<kScaled>(p);  // p in the sites' unit space (of the grid this one may be a window of)
  if constexpr (kPoints) rel = psd - s.seeds.points[site];
  // Triangle sites: the triangle prepared for every neighbour, and its plane (a lower bound, below).
  const TrianglePrep* tp = nullptr;
  if constexpr (!kPoints) tp = &prep.of(s.seeds, site);
  // The neighbouring bricks this push's links reach, looked up once (slots read once: a brick another thread creates
  // meanwhile reads as absent, which only costs a test its keys would have skipped; offer() goes to the real one).
  // Stand-ins replace missing bricks so the link loop tests no pointer: a brick not created yet reads as untouched
  // voxels, one beyond the grid as exact band voxels (skipped; other bands test for it).
  BrickState* nb[27];
  uint32_t nbi[27];
  nb[13] = pb;
  nbi[13] = e.brick;
  const Coord bcoord{pb->origin.x >> kBrickLog2, pb->origin.y >> kBrickLog2, pb->origin.z >> kBrickLog2};
  for (uint32_t m = s.links.bricksFor(l, e.dir); m; m &= m - 1) {
    const int i = std::countr_zero(m);
    std::atomic<BrickState*>* slot = table.neighbourSlot(e.brick, pslot, bcoord, i % 3 - 1, (i / 3) % 3 - 1,
                                                         i / 9 - 1, &nbi[i]);
    BrickState* b = slot ? slot->load(std::memory_order_acquire) : &outside_brick;
    nb[i] = b ? b : &absent_brick;
  }
  BrickState* const absent = &absent_brick;
  BrickState* const outside = &outside_brick;
  bool deferred = false;
  // Decides on one target whose key was read as k.
  auto decide = [&](const Link& d, uint64_t k) __attribute__((always_inline)) {
    const int goff = e.offset + d.offset;
    // The same site gives the same distance: nothing to offer (exact band voxels were skipped before their key;
    // triangle sites filtered these out while gathering).
    if constexpr (kPoints)
      if (keySite(k) == site) return;  // an untouched key's site is kNoSiteKey, never a pushed one
    float d2;
    if constexpr (kPoints) {
      const double x = rel.x + d.fx, y = rel.y + d.fy, z = rel.z + d.fz;
      d2 = float(x * x + y * y + z * z);
    } else {
      const Vec3d g{psd.x + d.fx, psd.y + d.fy, psd.z + d.fz};  // on a cubic grid integers: exact
      // The plane's distance bounds the triangle's from below: an offer it already shows to be worse is
      // rejected without the full test (float rounding is monotone, so the outcome is the same).
      const double plane = tp->unit_normal.dot(g - tp->plane_point);
      const float plane2 = float(plane * plane);
      if (k != kUntouched) {
        if (plane2 > keyDist2(k)) return;
      } else if (plane2 > admit2) {
        // Untouched and provably beyond the admission (the full test would get here too): ~40 % of a thin band's
        // full tests were these, the band's outer side.
        deferred |= defer;
        return;
      }
      d2 = float(tp->tri.dist2(g));
    }
    const uint64_t newkey = packKey(d2, d.dir, site);
    BrickState* gb = nb[d.brick];
    if (k != kUntouched) {
      if (newkey >= k || keyDist2(k) <= frozen2) return;  // no better, or final (delivered)
      if (lifespan && step > gb->expiry[goff].load(std::memory_order_relaxed)) return;  // FINISHED
    }
    if (d2 > admit2) {
      deferred |= defer;
      return;
    }
    const uint32_t gbi = nbi[d.brick];
    if (gb == absent) gb = table.getOrCreate(gbi, &tb.bricks);
    // A target propagates unless the stencil is fcc12's and it lies on the odd half.
    offerInline(s, gb, gbi, goff, newkey, d.propagates_to || ((psum + d.x + d.y + d.z) & 1) == 0, tb);
  };
  // Triangle sites: phase 1 gathers every target's key with independent loads, so their cache misses overlap;
  // phase 2 decides on them (keys may change in between: offer() re-checks, and a stale key only costs a test a
  // fresh one would have skipped). Point sites decide at once: their test is so cheap that the gathering cost more
  // than it saved (+50 % instructions in the push).
  struct Target {
    const Link* link;
    uint64_t key;
  };
  Target targets[32];
  int count = 0;
  // Only a brick reaching past the grid's far faces needs per-voxel bounds checks (the near faces are brick faces,
  // handled by the neighbouring bricks), and only seeds with regions a region test: the loop is compiled each way.
  auto scan = [&](auto edge_tag, auto region_tag) __attribute__((always_inline)) {
    for (const Link& d : s.links.linksFor(l, e.dir)) {
      if constexpr (decltype(edge_tag)::value)
        if (uint32_t(p.x + d.x) >= dx || uint32_t(p.y + d.y) >= dy || uint32_t(p.z + d.z) >= dz) continue;
      BrickState* const gb = nb[d.brick];
      const int goff = e.offset + d.offset;
      if constexpr (kExactBand) {
        if (gb->exact.test(goff)) continue;  // also every voxel of the stand-in beyond the grid
      } else if (gb == outside) {
        continue;
      }
      if constexpr (decltype(region_tag)::value)
        if (region_map[s.grid.denseIndex({p.x + d.x, p.y + d.y, p.z + d.z})] != region) continue;
      const uint64_t k = gb->key[goff].load(std::memory_order_relaxed);
      if constexpr (kPoints) {
        decide(d, k);
      } else {
        // The same site gives the same distance: nothing to offer. Half of the keys are such; dropped without a
        // branch on the key (gathering stays free of branches on its loads).
        targets[count] = {&d, k};
        count += keySite(k) != site;
      }
    }
  };
  const bool edge = pb->origin.x + kBrickSize > dims.x || pb->origin.y + kBrickSize > dims.y ||
                    pb->origin.z + kBrickSize > dims.z;
  if (region_map) edge ? scan(std::true_type{}, std::true_type{}) : scan(std::false_type{}, std::true_type{});
  else edge ? scan(std::true_type{}, std::false_type{}) : scan(std::false_type{}, std::false_type{});
  for (int i = 0; i < count; ++i) decide(*targets[i].link, targets[i].key);
  if (deferred) tb.deferred.push_back({e.brick, e.offset, uint8_t(kNoDirection), site});
}

}  // namespace

// Specialised on the site kind and on whether the band is exact: the exact-band test on every link cost point seeds
// ~5 % of the push's instructions when compiled in unconditionally.
namespace {
template <bool kScaled>
[[gnu::always_inline]] inline void pushWithScale(BandState& s, const FrontEntry& e, ThreadBuffers& tb, TrianglePrep& prep) {
  const bool exact = s.seeds.band_exact;
  if (s.seeds.kind == SiteKind::kPoint)
    exact ? pushFromT<true, true, kScaled>(s, e, tb, prep) : pushFromT<true, false, kScaled>(s, e, tb, prep);
  else
    exact ? pushFromT<false, true, kScaled>(s, e, tb, prep) : pushFromT<false, false, kScaled>(s, e, tb, prep);
}
// ... and on whether the grid is anisotropic (its voxels' unit-space positions scaled).
[[gnu::always_inline]] inline void pushWith(BandState& s, const FrontEntry& e, ThreadBuffers& tb, TrianglePrep& prep) {
  s.metric.scaled ? pushWithScale<true>(s, e, tb, prep) : pushWithScale<false>(s, e, tb, prep);
}
}  // namespace

void pushFrom(BandState& s, const FrontEntry& e, ThreadBuffers& tb) {
  TrianglePrep prep;
  pushWith(s, e, tb, prep);
}

void insertBand(BandState& s) {
  const auto& band = s.seeds.band;
  const size_t sites = s.seeds.siteCount();
  if (sites >= kMaxSites)
    throw std::invalid_argument(fmt::format("too many sites ({}; at most {})", sites, kMaxSites - 1));
  const double admit_limit = s.limit_vox + kLimitSlackVoxels * s.slack_scale;
  const float limit2 = std::isfinite(admit_limit) ? float(admit_limit * admit_limit) : INFINITY;
  const bool exact = s.seeds.band_exact;
  const bool triangles = s.seeds.kind == SiteKind::kTriangle;
  // Band voxels are checked inside the parallel loop (a serial pass over the band would be ~5 % of the insertion's
  // instructions); the first bad one (lowest index) is reported after it, so the error does not depend on threads.
  std::atomic<size_t> first_bad{~size_t(0)};
  s.step = 0;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, band.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = s.buffers.local();
    // Seeds list band voxels brick by brick (mesh: each brick's voxels in offset order): the brick, the exact bits
    // set in it (one atomic OR a word when the run of its voxels ends, not one a voxel) and the last triangle carry
    // over from one voxel to the next.
    Coord brick_coord{-1, -1, -1};
    uint32_t bi = BrickTable::kNoBrick;
    BrickState* b = nullptr;
    uint64_t exact_bits[kBrickVoxels / 64] = {};
    auto flush = [&] {
      for (int w = 0; w < kBrickVoxels / 64; ++w)
        if (exact_bits[w]) b->exact.words[w].fetch_or(std::exchange(exact_bits[w], 0), std::memory_order_relaxed);
    };
    // Not TrianglePrep: insertion needs no plane, whose normal and square root per triangle cost 14 % more
    // instructions here (callgrind, armadillo 256^3 hw3).
    std::optional<TriangleDistance> tri;
    uint32_t tri_site = kNoSiteKey;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 1024)) break;
      const BandVoxel& v = band[i];
      if (!s.grid.contains(v.voxel) || (v.site != kNoSite && v.site >= sites)) {
        size_t bad = first_bad.load(std::memory_order_relaxed);
        while (i < bad && !first_bad.compare_exchange_weak(bad, i, std::memory_order_relaxed)) {}
        continue;
      }
      const uint32_t site = toKeySite(v.site);
      float d2;
      if (triangles && site != kNoSiteKey) {  // SiteMetric::key2, with the triangle prepared once for a run of voxels
        if (site != tri_site) {
          const auto& t = s.seeds.triangles[site];
          tri.emplace(t[0], t[1], t[2]);
          tri_site = site;
        }
        d2 = float(tri->dist2(s.metric.unitsOf(v.voxel)));
      } else {
        d2 = s.metric.key2(site, s.metric.unitsOf(v.voxel));
      }
      if (d2 > limit2) continue;
      const Coord bc{v.voxel.x >> kBrickLog2, v.voxel.y >> kBrickLog2, v.voxel.z >> kBrickLog2};
      if (!b || !(bc == brick_coord)) {
        if (b) flush();
        brick_coord = bc;
        bi = s.brickIdOf(v.voxel);
        b = s.table.getOrCreate(bi, &tb.bricks);
      }
      const int off = brickOffset(v.voxel.x & 7, v.voxel.y & 7, v.voxel.z & 7);
      // Band voxels are first touched at step 0; kNoSite voxels (distance 0, nothing to offer) never push. An exact
      // band is not listed: its first push is made from the band list itself (stepFromBand).
      if (offer(s, b, bi, off, packKey(d2, kNoDirection, site), site != kNoSiteKey && !exact, tb) && exact)
        exact_bits[off >> 6] |= uint64_t(1) << (off & 63);
    }
    if (b) flush();
  });
  if (const size_t i = first_bad.load(); i != ~size_t(0)) {
    const BandVoxel& v = band[i];
    if (!s.grid.contains(v.voxel))
      throw std::invalid_argument(fmt::format("band voxel ({},{},{}) lies outside the grid", v.voxel.x, v.voxel.y,
                                              v.voxel.z));
    throw std::invalid_argument(fmt::format("band voxel names site {} of {}", v.site, sites));
  }
}

// Every band voxel offers its site, read from the band list (its key cannot have changed), so the band never goes
// through the front lists. All band voxels push, also those a stencil does not propagate from (fcc12's odd half):
// exact sites are the best candidates there are.
// The band step's blocks: a huge page of band voxels each.
constexpr size_t kBandBlockVoxels = kHugePageBytes / sizeof(BandVoxel);

void stepFromBand(BandState& s, bool give_back_band) {
  const auto& band = s.seeds.band;
  // Given back as it is read: block by block, each block's whole huge pages once its pushes are done (the whole band
  // beside the bricks this step makes was the band step's peak: 16 of a 512^3 teapot's 75 MiB).
  const size_t block = give_back_band ? kBandBlockVoxels : band.size();
  const char* const data = reinterpret_cast<const char*>(band.data());
  size_t given_back = 0;  // bytes from the band's start up to the end of the last huge page given back
  for (size_t b0 = 0; b0 < band.size(); b0 += block) {
    const size_t b1 = std::min(band.size(), b0 + block);
    tbb::parallel_for(tbb::blocked_range<size_t>(b0, b1, 1024), [&](const tbb::blocked_range<size_t>& r) {
      ThreadBuffers& tb = s.buffers.local();
      TrianglePrep prep;
      Coord brick_coord{-1, -1, -1};  // band voxels come brick by brick (see insertBand): the brick carries over
      uint32_t bi = BrickTable::kNoBrick;
      const BrickState* b = nullptr;
      for (size_t i = r.begin(); i != r.end(); ++i) {
        if (s.stoppingAt(i, 256)) return;
        const BandVoxel& v = band[i];
        if (v.site == kNoSite) continue;
        const Coord bc{v.voxel.x >> kBrickLog2, v.voxel.y >> kBrickLog2, v.voxel.z >> kBrickLog2};
        if (!(bc == brick_coord)) {
          brick_coord = bc;
          bi = s.table.idAt(bc);
          b = bi == BrickTable::kNoBrick ? nullptr : s.table.get(bi);
        }
        const int off = brickOffset(v.voxel.x & 7, v.voxel.y & 7, v.voxel.z & 7);
        if (!b || keySite(b->key[off].load(std::memory_order_relaxed)) != v.site) continue;  // beyond the limit
        pushWith(s, {bi, uint16_t(off), uint8_t(kNoDirection), v.site}, tb, prep);
      }
    });
    if (s.stopping()) return;
    // [0, b1) is read: the whole huge pages not given back yet go (the one straddling b1 with the next block).
    if (give_back_band) {
      const uintptr_t from = reinterpret_cast<uintptr_t>(data) + given_back;
      const uintptr_t to = roundDownToHugePage(reinterpret_cast<uintptr_t>(data) + b1 * sizeof(BandVoxel));
      if (to > from) {
        giveBackHugePages(const_cast<char*>(data) + given_back, to - from);
        given_back = to - reinterpret_cast<uintptr_t>(data);
      }
    }
  }
}

void step(BandState& s, const FrontList& front) {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, front.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = s.buffers.local();
    TrianglePrep prep;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 256)) return;
      pushWith(s, front[i], tb, prep);
    }
  });
}

namespace {

// Appends the threads' lists `field` (ThreadBuffers::next or ::deferred) to `to` in thread order, through
// `each(from, to)` for every entry, each list's copy split over the workers: on one thread it was a serial phase of
// every step (it also first-touches fresh pages, ~3 ms a MiB on some virtual machines, and a front at 1024^3 is tens
// of MB). A list is handed to `done(list)` as soon as it is copied, so a caller that frees it keeps the peak at the
// new list plus one old one, as the serial append did (all the old lists alive until the end of one parallel copy
// added 45 MB to a 1024^3 band's peak). False when the run must stop; `to` is then partly filled.
template <typename Each, typename Done>
bool gatherLists(BandState& s, FrontList& to, FrontList ThreadBuffers::*field, Each&& each, Done&& done) {
  size_t n = to.size();
  for (auto& tb : s.buffers) n += (tb.*field).size();
  to.reserve(n);  // exactly: resize alone may double the capacity
  for (auto& tb : s.buffers) {
    FrontList& list = tb.*field;
    const size_t base = to.size(), count = list.size();
    to.resize(base + count);  // uninitialised (FrontAllocator): the loop below writes every new entry
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        if (s.stoppingAt(i, 4096)) return;
        each(list[i], to[base + i]);
      }
    });
    if (s.stopping()) return false;
    done(list);
  }
  return true;
}

}  // namespace

void gatherFront(BandState& s, FrontList& front) {
  // The last front's storage is reused (its pages are touched already: a fresh page's first touch costs more than
  // the copy into it, ~3 ms a MiB on some virtual machines); grown, it is given back first rather than copied.
  front.clear();
  if (s.stopping()) return;  // the run ends: no need to copy the partial buffers
  size_t n = 0;
  for (auto& tb : s.buffers) n += tb.next.size();
  if (front.capacity() < n) FrontList().swap(front);
  // Snapshot each changed voxel's site as of the end of the step: the next step offers exactly these.
  const bool ok = gatherLists(
      s, front, &ThreadBuffers::next,
      [&](const FrontEntry& e, FrontEntry& out) {
        BrickState* b = s.table.get(e.brick);
        const uint64_t k = b->key[e.offset].load(std::memory_order_relaxed);
        // Every bit set in this word belongs to an entry of this front, so the whole word is cleared with a plain store
        // (threads clearing the same word all store 0): an atomic AND per entry was ~1/4 of the gather's time.
        b->listed.words[e.offset >> 6].store(0, std::memory_order_relaxed);
        out = {e.brick, e.offset, uint8_t(keyDir(k)), keySite(k)};
      },
      [](FrontList& list) { list.clear(); });  // its storage kept for the next step (releaseFronts gives it back)
  if (!ok) {
    front.clear();
    return;
  }
  // The next front is usually about this one's size: room for half as much again per thread (address space only
  // until written), instead of a chain of doublings whose copies touch fresh pages.
  reserveNext(s, n + n / 2);
}

void reserveNext(BandState& s, size_t entries) {
  const size_t share = entries / std::max<size_t>(1, s.buffers.size()) + 4096;
  for (auto& tb : s.buffers) {
    if (tb.next.capacity() >= share) continue;
    FrontList().swap(tb.next);  // empty: nothing to copy
    tb.next.reserve(share);
  }
}

void releaseFronts(BandState& s, FrontList& front) {
  FrontList().swap(front);
  for (auto& tb : s.buffers) FrontList().swap(tb.next);
}

bool collectDeferred(BandState& s) {
  return gatherLists(s, s.deferred, &ThreadBuffers::deferred, [](const FrontEntry& e, FrontEntry& out) { out = e; },
                     [](FrontList& list) { list.clear(); });
}

FrontList takeDeferred(BandState& s) {
  // Not sorted and deduplicated: an offer is held back once per push that made it, and a voxel pushes a site at
  // most once a slice, except when two threads lowering it at once both listed it; that duplicate replays the same
  // offers, which changes nothing. Bunny 256^3 hw 20 and 60 had no duplicates at all, and the parallel sort and
  // serial unique that removed them were ~2 % of the engine's instructions.
  if (!collectDeferred(s)) return FrontList();
  FrontList f;
  f.swap(s.deferred);
  return f;
}

void rearmLifespans(BandState& s) {
  const size_t n = s.pending_bricks.size();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (s.stoppingAt(i, 64)) return;
      BrickState* b = s.table.get(s.pending_bricks[i]);
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || b->emitted.test(off)) continue;
        b->expiry[off].store(s.expiryFor(keyDist2(k)), std::memory_order_relaxed);
      }
    }
  });
}

}  // namespace distband::band_internal
