// The active-band engine. See engine.h for the contract and docs/algorithm.md for the method.
//
// Per voxel the band stores one 64-bit key = (float squared distance in voxels) << 32 | site id (27 bits) << 5 |
// the stencil link the site arrived by (5 bits; see kSiteBits below). Positive floats order like their bit patterns,
// so "better site" is an integer minimum and one atomic CAS updates distance, site and link together; ties go to the
// lower site id, which keeps the result independent of thread scheduling.
//
// A step is Jacobi-like: every voxel that changed in the previous step offers the site it held at the end of that
// step (snapshotted in the front list) to its stencil neighbours; neighbours keep the minimum. Pushes from voxels
// that did not change would repeat offers already made, so only changed voxels work (the paper's band iteration
// gives the same field; the lifespan then only decides when a voxel stops accepting offers).
#include "core/engine.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>

#include <malloc.h>
#include <sys/mman.h>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/geometry.h"
#include "core/interruptible.h"
#include "core/thread_arena.h"

namespace distband {

std::string_view modeName(PropagationMode mode) { return mode == PropagationMode::kPaper ? "paper" : "exact"; }

bool parseMode(std::string_view name, PropagationMode* mode) {
  if (name == "paper") *mode = PropagationMode::kPaper;
  else if (name == "exact") *mode = PropagationMode::kExact;
  else return false;
  return true;
}

StencilKind defaultStencil(SiteKind kind) {
  return kind == SiteKind::kTriangle ? StencilKind::kFcc12 : StencilKind::kCubic26;
}

int defaultLifespanMargin(StencilKind stencil) {
  // The paper's t_min/t_max bounds hold for arrival times counted from the site; our clock starts at the initial
  // band, up to ~1 voxel (1–2 steps) off the site. See docs/algorithm.md and the lifespan tests.
  switch (stencil) {
    case StencilKind::kCubic6: return 3;
    case StencilKind::kCubic18: return 2;
    case StencilKind::kCubic26: return 2;
    case StencilKind::kFcc12: return 2;
  }
  return 2;
}

std::string validateOptions(const Grid& grid, const EngineOptions& o) {
  if (std::string e = grid.validate(); !e.empty()) return "grid: " + e;
  if (!(o.segment_length_world >= 0) || std::isinf(o.segment_length_world))
    return fmt::format("segment_length must be finite and >= 0 (got {})", o.segment_length_world);
  if (!(o.limit_world > 0)) return fmt::format("limit must be > 0 (got {})", o.limit_world);
  if (o.threads < 0 || o.threads > 4096) return fmt::format("threads must be in [0, 4096] (got {})", o.threads);
  if (std::isnan(o.lifespan_alpha)) return "lifespan_alpha must not be NaN";
  if (o.lifespan_margin > 1000) return "lifespan_margin must be <= 1000";
  if (o.segment_length_world > 0 && std::isfinite(o.limit_world) &&
      o.limit_world / o.segment_length_world > 100000)
    return "limit / segment_length must be <= 100000 segments";
  return {};
}

namespace {

// ---- Per-voxel key ------------------------------------------------------------------------------------------------
// 64 bits: float squared distance (voxels) | 27-bit site | 5-bit source direction. Positive floats order like their
// bit patterns, so "better" is an integer minimum and one atomic CAS updates everything together; distance ties go
// to the lower site, which keeps the field independent of thread scheduling. The direction is a stencil link along
// which the held site was offered (kNoDirection for the band, corrections and replays); an offer of the site a voxel
// already holds is never taken, so which valid direction is kept may vary, but it only selects offers that would be
// redundant either way (see buildLinkTables).
constexpr uint64_t kUntouched = ~uint64_t(0);
constexpr int kSiteBits = 27;
constexpr uint32_t kSiteMask = (1u << kSiteBits) - 1;
constexpr uint32_t kNoSiteKey = kSiteMask;  // kNoSite in the key
constexpr uint32_t kMaxSites = kSiteMask;   // site ids must stay below this
constexpr uint32_t kNoDirection = 31;

inline uint64_t packKey(float d2, uint32_t dir, uint32_t site) {
  return (uint64_t(std::bit_cast<uint32_t>(d2)) << 32) | (uint64_t(site) << 5) | dir;
}
inline float keyDist2(uint64_t k) { return std::bit_cast<float>(uint32_t(k >> 32)); }
inline uint32_t keySite(uint64_t k) { return uint32_t(k) >> 5; }
inline uint32_t keyDir(uint64_t k) { return uint32_t(k) & 31; }
inline uint32_t toKeySite(uint32_t site) { return site == kNoSite ? kNoSiteKey : site; }

constexpr uint32_t kOutsideGrid = ~uint32_t(0);
constexpr uint16_t kNeverExpires = 0xFFFF;
constexpr int kMaxSteps = 65000;  // expiry holds 16-bit step numbers
// Offers are admitted this many voxels beyond a segment's threshold, while only voxels within the threshold are
// frozen and delivered: a closest site whose path briefly runs outside the threshold still arrives. At the limit the
// slack is smaller: it is paid in work and memory on every query, and nothing beyond the limit is delivered.
constexpr double kAdmitSlackVoxels = 2.0;
constexpr double kLimitSlackVoxels = 1.0;
// With many competing sites the first site to reach a voxel (fewest steps) is often not its closest, and every
// later improvement is propagated again. Admitting offers in distance slices of this width (replaying the held-back
// ones when a slice's front empties) brings them in nearly nearest-first: about half the updates for meshes and
// volumes. With few sites there is little to gain and the replays would cost, so it starts at kBucketMinSites.
// Triangle sites (fcc12 by default) do best with wider slices: 5-10 % less time at 20- and 60-voxel bands than 4.
constexpr double kBucketVoxels = 4.0;
constexpr double kTriangleBucketVoxels = 8.0;
constexpr size_t kBucketMinSites = 256;

/// One bit per voxel of a brick. set() and clear() are atomic read-modify-writes (other threads may set other bits
/// of the same word); set() tells whether this call set the bit.
struct VoxelBits {
  std::atomic<uint64_t> words[kBrickVoxels / 64] = {};
  bool test(int i) const { return (words[i >> 6].load(std::memory_order_relaxed) >> (i & 63)) & 1; }
  bool set(int i) {
    const uint64_t bit = uint64_t(1) << (i & 63);
    return !(words[i >> 6].fetch_or(bit, std::memory_order_relaxed) & bit);
  }
  void clear(int i) { words[i >> 6].fetch_and(~(uint64_t(1) << (i & 63)), std::memory_order_relaxed); }
};

// 8 bytes and 5 bits a voxel (2 bytes more with a lifespan): memory follows the touched bricks.
struct BrickState {
  BrickState(Coord o, bool with_lifespan) : origin(o) {
    for (int i = 0; i < kBrickVoxels; ++i) key[i].store(kUntouched, std::memory_order_relaxed);
    if (with_lifespan) {
      expiry = std::make_unique<std::atomic<uint16_t>[]>(kBrickVoxels);
      for (int i = 0; i < kBrickVoxels; ++i) expiry[i].store(kNeverExpires, std::memory_order_relaxed);
    }
  }
  Coord origin;
  std::atomic<bool> pending{false};  // listed for emission (holds touched, not yet emitted voxels)
  std::atomic<uint64_t> key[kBrickVoxels];
  VoxelBits listed;   // already in the next front
  VoxelBits emitted;  // delivered (final)
  VoxelBits dirty;    // changed since the last correction round (listed in ThreadBuffers::dirty)
  VoxelBits queued;   // already a candidate of the current correction round
  // A band voxel of a Seeds::band_exact band (set before the first step, then only read). One cache line, tested
  // before the voxel's key is loaded.
  VoxelBits exact;
  std::unique_ptr<std::atomic<uint16_t>[]> expiry;  // paper mode: last step in which a voxel accepts offers
};

struct VoxelRef {
  uint32_t brick;
  uint16_t offset;
};

/// A voxel that offers a site: the site and the direction it arrived from, as of the end of the previous step.
struct FrontEntry {
  uint32_t brick;
  uint16_t offset;
  uint8_t dir;
  uint32_t site;
};

// Allocator of the front lists. Lists of 16 MiB or more are mapped and unmapped directly: glibc would otherwise
// serve them from its heaps once it has seen large blocks freed, and the holes they leave stay resident while the
// bricks keep growing. Smaller ones stay on the heap, whose reused pages cost no page faults.
template <class T>
struct FrontAllocator {
  using value_type = T;
  static constexpr size_t kMapBytes = size_t(16) << 20;
  FrontAllocator() = default;
  template <class U>
  FrontAllocator(const FrontAllocator<U>&) {}
  T* allocate(size_t n) {
    const size_t bytes = n * sizeof(T);
    if (bytes < kMapBytes) return std::allocator<T>().allocate(n);
    void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) {
    const size_t bytes = n * sizeof(T);
    if (bytes < kMapBytes) std::allocator<T>().deallocate(p, n);
    else ::munmap(p, bytes);
  }
  template <class U>
  bool operator==(const FrontAllocator<U>&) const { return true; }
};
using FrontList = std::vector<FrontEntry, FrontAllocator<FrontEntry>>;

struct ThreadBuffers {
  FrontList next;       // voxels changed in this step (site filled in after the step)
  FrontList deferred;   // offers held back beyond the admission threshold (voxel, site)
  std::vector<uint32_t> pending;      // bricks that got their first unemitted voxel
  int64_t bricks = 0;  // allocated by this thread
  std::vector<std::pair<VoxelRef, uint64_t>> corrections;
  std::vector<VoxelRef> dirty;        // changed since the last correction round (exact mode)
  int64_t updates = 0;
};

struct SiteMetric {
  const Seeds& seeds;
  // Squared distance in voxels from voxel (x,y,z) to a site (key form), in double (the emitted value) ...
  double dist2(uint32_t site, double x, double y, double z) const {
    if (site == kNoSiteKey) return 0.0;
    // Sites live in the index space of the grid this one is a window of; integer offsets add exactly, so a tile
    // computes the same doubles as the whole grid would.
    const Vec3d p{x + seeds.site_offset.x, y + seeds.site_offset.y, z + seeds.site_offset.z};
    if (seeds.kind == SiteKind::kPoint) return (p - seeds.points[site]).lengthSqr();
    const auto& t = seeds.triangles[site];
    return TriangleDistance(t[0], t[1], t[2]).dist2(p);
  }
  // ... and rounded to float for the key.
  float key2(uint32_t site, double x, double y, double z) const { return float(dist2(site, x, y, z)); }
};

class BandRun {
 public:
  BandRun(const Grid& grid, const Seeds& seeds, const EngineOptions& opt, const SegmentCallback& cb,
          std::vector<BandVoxel>* owned_band)
      : grid_(grid),
        seeds_(seeds),
        owned_band_(owned_band),
        opt_(opt),
        cb_(cb),
        stencil_(Stencil::get(opt.stencil.value_or(defaultStencil(seeds.kind)))),
        metric_{seeds},
        dims_(grid.dims()),
        bdims_(grid.brickDims()),
        table_(size_t(bdims_.x) * bdims_.y * bdims_.z),
        region_(seeds.region ? seeds.region->data() : nullptr) {
    for (auto& p : table_) p.store(nullptr, std::memory_order_relaxed);
    buildLinkTables();
    if (opt.mode == PropagationMode::kPaper) {
      alpha_ = opt.lifespan_alpha < 0 ? stencil_.alpha : opt.lifespan_alpha;
      margin_ = opt.lifespan_margin < 0 ? defaultLifespanMargin(stencil_.kind) : opt.lifespan_margin;
      use_lifespan_ = std::isfinite(alpha_);
    }
    max_link_ = stencil_.fcc ? std::sqrt(2.0) : 0.0;
    if (!stencil_.fcc)
      for (const Coord& l : stencil_.links)
        max_link_ = std::max(max_link_, std::sqrt(double(l.x * l.x + l.y * l.y + l.z * l.z)));
    const double h = grid.voxelSize();
    limit_vox_ = opt.limit_world / h;
    segment_vox_ = opt.segment_length_world / h;
  }

  ~BandRun() { releaseBricks(); }

  EngineResult run();

 private:
  struct Link {
    int x, y, z;
    int offset;          // added to the source's brick offset: the target's offset in its own brick
    int brick;           // which of the 3x3x3 neighbouring bricks holds the target (13: the same one)
    uint32_t dir;        // index of the link in the stencil (stored in the target's key)
    double fx, fy, fz;   // the link as doubles, so point-site distances need no conversions
    bool propagates_to;  // true when the target always propagates (every cubic stencil)
  };

  void buildLinkTables();
  const std::vector<Link>& linksFor(const Coord& local, uint32_t dir) const {
    auto cls = [](int v) { return v == 0 ? 0 : (v == kBrickSize - 1 ? 2 : 1); };
    return link_tables_[(cls(local.z) * 9 + cls(local.y) * 3 + cls(local.x)) * 32 + dir];
  }

  /// Whether the run must stop. Cheap: a relaxed load once tripped (and a clock read while a deadline is pending).
  bool stopping() const { return isInterrupted(opt_.interrupter); }
  /// stopping(), polled at item i of a parallel range every `every` items (a power of two). A poll per range is not
  /// enough: TBB's auto_partitioner hands out ranges of up to 1/(4 x threads) of a loop, which at 1024^3 is a few
  /// hundred milliseconds of work. `every` keeps a poll interval near 0.1 ms of the loop's work per item.
  bool stoppingAt(size_t i, size_t every) const { return (i & (every - 1)) == 0 && stopping(); }
  /// Appends `from` to `to` in slices of 256 Ki entries with a poll between them; false when the run must stop.
  /// The copy first-touches fresh pages on one thread, ~3 ms a MiB on some virtual machines, and a front at 1024^3
  /// is tens of MB. Callers reserve the total first (one allocation for all the threads' lists).
  template <typename List>
  bool appendPolled(List& to, const List& from) const {
    constexpr size_t kSlice = size_t(256) << 10;
    for (size_t i = 0; i < from.size(); i += kSlice) {
      if (stopping()) return false;
      to.insert(to.end(), from.begin() + i, from.begin() + std::min(from.size(), i + kSlice));
    }
    return true;
  }

  uint32_t brickIndex(int x, int y, int z) const {
    return uint32_t(((z >> kBrickLog2) * bdims_.y + (y >> kBrickLog2)) * bdims_.x + (x >> kBrickLog2));
  }
  Coord brickOrigin(uint32_t bi) const {
    const int bx = int(bi % bdims_.x), by = int((bi / bdims_.x) % bdims_.y), bz = int(bi / (bdims_.x * bdims_.y));
    return {bx << kBrickLog2, by << kBrickLog2, bz << kBrickLog2};
  }
  uint8_t regionOf(const Coord& c) const { return region_ ? region_[grid_.denseIndex(c)] : 0; }
  uint64_t keyAt(const Coord& c) const {
    if (!grid_.contains(c)) return kUntouched;
    BrickState* b = table_[brickIndex(c.x, c.y, c.z)].load(std::memory_order_relaxed);
    return b ? b->key[brickOffset(c.x & 7, c.y & 7, c.z & 7)].load(std::memory_order_relaxed) : kUntouched;
  }

  BrickState* getOrCreate(uint32_t bi, ThreadBuffers& tb) {
    BrickState* b = table_[bi].load(std::memory_order_acquire);
    if (b) return b;
    auto* fresh = new BrickState(brickOrigin(bi), use_lifespan_);
    if (table_[bi].compare_exchange_strong(b, fresh, std::memory_order_acq_rel)) {
      ++tb.bricks;
      return fresh;
    }
    delete fresh;
    return b;
  }

  // The paper's lifespan, t_max = (1 + alpha) * t_min, with t_min taken from the voxel's first distance beyond the
  // segment's lower bound (t_min = distance / longest link) rather than from its first-touch step. The two agree
  // when the band sits on the sites; the distance form stays right when it does not (seeds outside the grid, a
  // segment restarting from the finished region). See docs/algorithm.md.
  uint16_t expiryFor(float d2) const {
    const double beyond = std::max(0.0, std::sqrt(double(d2)) - lower_vox_);
    const double exp = segment_start_step_ + std::ceil((1.0 + alpha_) * beyond / max_link_) + margin_;
    return uint16_t(std::min(exp, double(kMaxSteps)));
  }

  // Offers `newkey` to voxel (b, off). Returns true when it lowered the voxel's key.
  bool offer(BrickState* b, uint32_t bi, int off, uint64_t newkey, bool propagates, ThreadBuffers& tb) {
    uint64_t k = b->key[off].load(std::memory_order_relaxed);
    while (newkey < k) {
      if (b->key[off].compare_exchange_weak(k, newkey, std::memory_order_relaxed)) {
        ++tb.updates;
        if (k == kUntouched) {
          if (use_lifespan_) b->expiry[off].store(expiryFor(keyDist2(newkey)), std::memory_order_relaxed);
          if (!b->pending.load(std::memory_order_relaxed) && !b->pending.exchange(true)) tb.pending.push_back(bi);
        }
        if (collect_dirty_ && !b->dirty.test(off) && b->dirty.set(off))
          tb.dirty.push_back({bi, uint16_t(off)});
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

  void pushFrom(const FrontEntry& e, ThreadBuffers& tb);
  template <bool kPoints, bool kExactBand>
  void pushFromT(const FrontEntry& e, ThreadBuffers& tb);
  void insertBand();
  void stepFromBand();
  void step(FrontList& front);
  bool isBoundary(const Coord& q, uint64_t k) const;
  void scanAndCheck();
  void checkVoxel(const VoxelRef& v, const Coord& q, uint64_t k, uint64_t* block, ThreadBuffers& tb) const;
  FrontList correct(bool first_round);
  void gatherBlock(const Coord& q, uint64_t* block) const;
  bool emitSegment(int index, double lower_vox, double upper_vox, bool nothing_deferred, SegmentStats& stats);
  void buildChunk(size_t c0, size_t c1, const std::vector<uint32_t>& slot, const std::vector<uint8_t>& keep,
                  uint32_t base, bool triangles, std::vector<Brick>& out);
  int64_t closestFeature(uint32_t site, const Coord& voxel) const;
  void rearmLifespans();
  void releaseBricks();
  void collectPending();

  const Grid& grid_;
  const Seeds& seeds_;
  std::vector<BandVoxel>* owned_band_;  // seeds_.band when the caller handed the seeds over: freed once inserted
  const EngineOptions& opt_;
  const SegmentCallback& cb_;
  const Stencil& stencil_;
  SiteMetric metric_;
  Coord dims_, bdims_;
  std::vector<std::atomic<BrickState*>> table_;
  const uint8_t* region_;
  std::vector<Link> links_;
  // links_ specialised for each position class of the source in its brick (per axis local 0, 1..6 or 7) and each
  // arrival direction: links whose target the previous offerer already reached with the same site are dropped.
  std::vector<Link> link_tables_[27 * 32];
  double alpha_ = 0;
  int margin_ = 0;
  bool use_lifespan_ = false;
  double max_link_ = 1;     // longest link between propagating voxels (voxels per step at best)
  double lower_vox_ = 0;    // the current segment's lower distance bound
  bool correcting_ = false;    // exact mode: second-ring correction at the end of each segment
  bool collect_dirty_ = false;  // after a segment's first correction round
  double limit_vox_ = 0, segment_vox_ = 0;

  int step_ = 0;
  int segment_start_step_ = 0;
  float thr2_ = 0;       // voxels within this squared distance are delivered at the end of the segment
  float admit2_ = 0;     // offers beyond this squared distance wait for a later segment
  float frozen2_ = -1;   // voxels at or below this squared distance are final (delivered)
  bool thr_is_limit_ = false;
  bool defer_ = false;   // offers beyond admit2_ are held back for a later slice or segment (not past the limit)
  double bucket_vox_ = 0;

  tbb::enumerable_thread_specific<ThreadBuffers> buffers_;
  std::vector<uint32_t> pending_bricks_;
  FrontList deferred_;
  int64_t corrections_ = 0;
};

void BandRun::buildLinkTables() {
  const std::vector<Coord>& sl = stencil_.links;
  auto isLinkOrZero = [&](const Coord& v) {
    if (v.x == 0 && v.y == 0 && v.z == 0) return true;
    return std::find(sl.begin(), sl.end(), v) != sl.end();
  };
  for (size_t i = 0; i < sl.size(); ++i) {
    const Coord& l = sl[i];
    links_.push_back({l.x, l.y, l.z, l.x * 64 + l.y * 8 + l.z, 13, uint32_t(i), double(l.x), double(l.y), double(l.z),
                      !stencil_.fcc});
  }
  const int rep_local[3] = {0, 1, kBrickSize - 1};  // a representative local coordinate of each class
  for (int c = 0; c < 27; ++c) {
    const Coord src{rep_local[c % 3], rep_local[(c / 3) % 3], rep_local[c / 9]};
    for (uint32_t dir = 0; dir < 32; ++dir) {
      if (dir != kNoDirection && dir >= sl.size()) continue;
      for (Link link : links_) {
        // The source received its site along link `dir` from Q = source - sl[dir], which offered the same site
        // to all of its own links one step earlier: a target that is one of them (or Q) gains nothing.
        if (dir != kNoDirection) {
          const Coord& u = sl[dir];
          if (isLinkOrZero({link.x + u.x, link.y + u.y, link.z + u.z})) continue;
        }
        const int lx = src.x + link.x, ly = src.y + link.y, lz = src.z + link.z;
        const int sx = lx >> kBrickLog2, sy = ly >> kBrickLog2, sz = lz >> kBrickLog2;
        link.brick = (sz + 1) * 9 + (sy + 1) * 3 + (sx + 1);
        link.offset = brickOffset(lx & 7, ly & 7, lz & 7) - brickOffset(src.x, src.y, src.z);
        link_tables_[c * 32 + dir].push_back(link);
      }
    }
  }
}

// Specialised on the site kind and on whether the band is exact: the exact-band test on every link cost point seeds
// ~5 % of the push's instructions when compiled in unconditionally.
void BandRun::pushFrom(const FrontEntry& e, ThreadBuffers& tb) {
  const bool exact = seeds_.band_exact;
  if (seeds_.kind == SiteKind::kPoint) exact ? pushFromT<true, true>(e, tb) : pushFromT<true, false>(e, tb);
  else exact ? pushFromT<false, true>(e, tb) : pushFromT<false, false>(e, tb);
}

template <bool kPoints, bool kExactBand>
void BandRun::pushFromT(const FrontEntry& e, ThreadBuffers& tb) {
  // Members copied to locals: the atomics and buffer writes below would otherwise force reloads every link.
  BrickState* const pb = table_[e.brick].load(std::memory_order_relaxed);
  const Coord l = brickLocal(e.offset);
  const Coord p = pb->origin + l;
  const uint32_t site = e.site;
  const uint8_t* const region_map = region_;
  const uint8_t region = regionOf(p);
  const uint32_t dx = uint32_t(dims_.x), dy = uint32_t(dims_.y), dz = uint32_t(dims_.z);
  const float admit2 = admit2_, frozen2 = frozen2_;
  const bool lifespan = use_lifespan_, defer = defer_;
  const int step = step_;
  // Point sites: the offset from the site to p, so a neighbour's squared distance is three multiply-adds.
  Vec3d rel{};
  const Coord ps = p + seeds_.site_offset;  // p in the sites' index space (the grid this one may be a window of)
  if constexpr (kPoints) rel = Vec3d{double(ps.x), double(ps.y), double(ps.z)} - seeds_.points[site];
  // Triangle sites: one precomputed triangle for every neighbour, and its plane (a lower bound, below).
  std::optional<TriangleDistance> tri;
  Vec3d plane_point{}, unit_normal{};
  if constexpr (!kPoints) {
    const auto& t = seeds_.triangles[site];
    tri.emplace(t[0], t[1], t[2]);
    const Vec3d n = (t[1] - t[0]).cross(t[2] - t[0]);
    const double len2 = n.lengthSqr();
    plane_point = t[0];
    unit_normal = len2 > 0 ? n * (1.0 / std::sqrt(len2)) : Vec3d{};  // degenerate: bound 0, never rejects
  }
  // Only a brick reaching past the grid's far faces needs per-voxel bounds checks (the near faces are brick
  // faces, handled by the neighbouring-brick lookup).
  const bool edge = pb->origin.x + kBrickSize > dims_.x || pb->origin.y + kBrickSize > dims_.y ||
                    pb->origin.z + kBrickSize > dims_.z;
  // The 3x3x3 neighbouring bricks, looked up once each on demand.
  uint32_t nbr_index[27];
  uint32_t known = 1u << 13;  // bit i: nbr_index[i] valid; 13 is this brick
  nbr_index[13] = e.brick;
  const Coord bcoord{pb->origin.x >> kBrickLog2, pb->origin.y >> kBrickLog2, pb->origin.z >> kBrickLog2};
  bool deferred = false;
  // Decides on one target whose key was read as k.
  auto decide = [&](const Link& d, BrickState* gb, uint32_t gbi, uint64_t k) {
    const int goff = e.offset + d.offset;
    // The same site gives the same distance: nothing to offer (exact band voxels were skipped before their key).
    if (k != kUntouched && keySite(k) == site) return;
    float d2;
    if constexpr (kPoints) {
      const double x = rel.x + d.fx, y = rel.y + d.fy, z = rel.z + d.fz;
      d2 = float(x * x + y * y + z * z);
    } else {
      const Vec3d g{double(ps.x + d.x), double(ps.y + d.y), double(ps.z + d.z)};
      // The plane's distance bounds the triangle's from below: an offer it already shows to be worse is
      // rejected without the full test (float rounding is monotone, so the outcome is the same).
      const double plane = unit_normal.dot(g - plane_point);
      if (k != kUntouched && float(plane * plane) > keyDist2(k)) return;
      d2 = float(tri->dist2(g));
    }
    const uint64_t newkey = packKey(d2, d.dir, site);
    if (k != kUntouched) {
      if (newkey >= k || keyDist2(k) <= frozen2) return;  // no better, or final (delivered)
      if (lifespan && step > gb->expiry[goff].load(std::memory_order_relaxed)) return;  // FINISHED
    }
    if (d2 > admit2) {
      deferred |= defer;
      return;
    }
    if (!gb) gb = getOrCreate(gbi, tb);
    offer(gb, gbi, goff, newkey, d.propagates_to || stencil_.propagates({p.x + d.x, p.y + d.y, p.z + d.z}), tb);
  };
  // Triangle sites: phase 1 gathers every target's brick and key with independent loads, so their cache misses
  // overlap; phase 2 decides on them (keys may change in between: offer() re-checks, and a stale key only costs a
  // test a fresh one would have skipped). Point sites decide at once: their test is so cheap that the gathering
  // cost more than it saved (+50 % instructions in the push).
  struct Target {
    const Link* link;
    BrickState* brick;
    uint32_t brick_index;
    uint64_t key;
  };
  Target targets[32];
  int count = 0;
  for (const Link& d : linksFor(l, e.dir)) {
    if (edge && (uint32_t(p.x + d.x) >= dx || uint32_t(p.y + d.y) >= dy || uint32_t(p.z + d.z) >= dz)) continue;
    const int goff = e.offset + d.offset;
    BrickState* gb = pb;
    uint32_t gbi = e.brick;
    if (d.brick != 13) {
      if (!(known & (1u << d.brick))) {
        known |= 1u << d.brick;
        const int bx = bcoord.x + d.brick % 3 - 1, by = bcoord.y + (d.brick / 3) % 3 - 1,
                  bz = bcoord.z + d.brick / 9 - 1;
        nbr_index[d.brick] = (bx < 0 || by < 0 || bz < 0 || bx >= bdims_.x || by >= bdims_.y || bz >= bdims_.z)
                                 ? kOutsideGrid
                                 : uint32_t((size_t(bz) * bdims_.y + by) * bdims_.x + bx);
      }
      gbi = nbr_index[d.brick];
      if (gbi == kOutsideGrid) continue;
      gb = table_[gbi].load(std::memory_order_acquire);
    }
    if (kExactBand && gb && gb->exact.test(goff)) continue;
    if (region_map && region_map[grid_.denseIndex({p.x + d.x, p.y + d.y, p.z + d.z})] != region) continue;
    const uint64_t k = gb ? gb->key[goff].load(std::memory_order_relaxed) : kUntouched;
    if constexpr (kPoints) decide(d, gb, gbi, k);
    else targets[count++] = {&d, gb, gbi, k};
  }
  for (int i = 0; i < count; ++i) decide(*targets[i].link, targets[i].brick, targets[i].brick_index, targets[i].key);
  if (deferred) tb.deferred.push_back({e.brick, e.offset, uint8_t(kNoDirection), site});
}

void BandRun::insertBand() {
  const auto& band = seeds_.band;
  if (seeds_.siteCount() >= kMaxSites)
    throw std::invalid_argument(fmt::format("too many sites ({}; at most {})", seeds_.siteCount(), kMaxSites - 1));
  const double admit_limit = limit_vox_ + kLimitSlackVoxels;
  const float limit2 = std::isfinite(admit_limit) ? float(admit_limit * admit_limit) : INFINITY;
  for (const BandVoxel& v : band) {
    if (!grid_.contains(v.voxel))
      throw std::invalid_argument(fmt::format("band voxel ({},{},{}) lies outside the grid", v.voxel.x, v.voxel.y,
                                              v.voxel.z));
    if (v.site != kNoSite && v.site >= seeds_.siteCount())
      throw std::invalid_argument(fmt::format("band voxel names site {} of {}", v.site, seeds_.siteCount()));
  }
  step_ = 0;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, band.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = buffers_.local();
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 1024)) return;
      const BandVoxel& v = band[i];
      const uint32_t site = toKeySite(v.site);
      const float d2 = metric_.key2(site, v.voxel.x, v.voxel.y, v.voxel.z);
      if (d2 > limit2) continue;
      const uint32_t bi = brickIndex(v.voxel.x, v.voxel.y, v.voxel.z);
      BrickState* b = getOrCreate(bi, tb);
      const int off = brickOffset(v.voxel.x & 7, v.voxel.y & 7, v.voxel.z & 7);
      // Band voxels are first touched at step 0; kNoSite voxels (distance 0, nothing to offer) never push. An exact
      // band is not listed: its first push is made from the band list itself (stepFromBand).
      if (offer(b, bi, off, packKey(d2, kNoDirection, site), site != kNoSiteKey && !seeds_.band_exact, tb) &&
          seeds_.band_exact)
        b->exact.set(off);
    }
  });
}

// The first step of an exact band: every band voxel offers its site, read from the band list (its key cannot have
// changed), so the band never goes through the front lists. All band voxels push, also those a stencil does not
// propagate from (fcc12's odd half): exact sites are the best candidates there are.
void BandRun::stepFromBand() {
  const auto& band = seeds_.band;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, band.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = buffers_.local();
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 256)) return;
      const BandVoxel& v = band[i];
      if (v.site == kNoSite) continue;
      const uint32_t bi = brickIndex(v.voxel.x, v.voxel.y, v.voxel.z);
      const BrickState* b = table_[bi].load(std::memory_order_relaxed);
      const int off = brickOffset(v.voxel.x & 7, v.voxel.y & 7, v.voxel.z & 7);
      if (!b || keySite(b->key[off].load(std::memory_order_relaxed)) != v.site) continue;  // beyond the limit
      pushFrom({bi, uint16_t(off), uint8_t(kNoDirection), v.site}, tb);
    }
  });
}

void BandRun::step(FrontList& front) {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, front.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = buffers_.local();
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 256)) return;
      pushFrom(front[i], tb);
    }
  });
}

// A voxel may hold a site that is not its closest only where different sites meet: true when a propagating stencil
// neighbour (same region) holds a different site.
bool BandRun::isBoundary(const Coord& q, uint64_t k) const {
  const uint8_t region = regionOf(q);
  for (const Link& d : links_) {
    const Coord n{q.x - d.x, q.y - d.y, q.z - d.z};
    if (!stencil_.propagates(n)) continue;
    const uint64_t nk = keyAt(n);
    if (nk == kUntouched || keySite(nk) == keySite(k) || keySite(nk) == kNoSiteKey) continue;
    if (region_ && regionOf(n) != region) continue;
    return true;
  }
  return false;
}

// Checks every voxel of the current segment (delivered at its end) that sits where different sites meet. A brick
// whose voxels all hold one site, like its 26 neighbours, has none and is skipped whole: far from Voronoi boundaries
// (most of the volume for point seeds) the scan costs one pass over a brick's keys.
void BandRun::scanAndCheck() {
  const size_t n = pending_bricks_.size();
  constexpr uint32_t kMixed = ~uint32_t(0), kEmpty = ~uint32_t(0) - 1;
  // The one site all touched voxels of a brick hold, kMixed if they differ, kEmpty if none is touched.
  auto uniformSite = [&](const BrickState* b) {
    uint32_t u = kEmpty;
    for (int off = 0; off < kBrickVoxels && u != kMixed; ++off) {
      const uint64_t k = b->key[off].load(std::memory_order_relaxed);
      if (k == kUntouched) continue;
      u = (u == kEmpty || u == keySite(k)) ? keySite(k) : kMixed;
    }
    return u;
  };
  std::vector<uint32_t> uniform(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 64)) return;
      uniform[i] = uniformSite(table_[pending_bricks_[i]].load(std::memory_order_relaxed));
    }
  });
  if (stopping()) return;
  // Of any brick by index: pending bricks from the table above, the others (all delivered) scanned on demand.
  auto uniformOf = [&](uint32_t bi) -> uint32_t {
    const auto it = std::lower_bound(pending_bricks_.begin(), pending_bricks_.end(), bi);
    if (it != pending_bricks_.end() && *it == bi) return uniform[size_t(it - pending_bricks_.begin())];
    const BrickState* b = table_[bi].load(std::memory_order_relaxed);
    return b ? uniformSite(b) : kEmpty;
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    ThreadBuffers& tb = buffers_.local();
    uint64_t block[125];
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 4)) return;
      const uint32_t bi = pending_bricks_[i];
      BrickState* b = table_[bi].load(std::memory_order_relaxed);
      const Coord bc{b->origin.x >> kBrickLog2, b->origin.y >> kBrickLog2, b->origin.z >> kBrickLog2};
      if (uniform[i] != kMixed && !region_) {
        bool all_same = true;
        for (int dz = -1; dz <= 1 && all_same; ++dz)
          for (int dy = -1; dy <= 1 && all_same; ++dy)
            for (int dx = -1; dx <= 1 && all_same; ++dx) {
              const int x = bc.x + dx, y = bc.y + dy, z = bc.z + dz;
              if (x < 0 || y < 0 || z < 0 || x >= bdims_.x || y >= bdims_.y || z >= bdims_.z) continue;
              const uint32_t u = uniformOf(uint32_t((size_t(z) * bdims_.y + y) * bdims_.x + x));
              all_same = u == kEmpty || u == uniform[i];
            }
        if (all_same) continue;
      }
      // The 27 bricks around this one (null outside the grid or untouched), for the per-voxel test.
      BrickState* nbr[27];
      for (int j = 0; j < 27; ++j) {
        const int x = bc.x + j % 3 - 1, y = bc.y + (j / 3) % 3 - 1, z = bc.z + j / 9 - 1;
        nbr[j] = (x < 0 || y < 0 || z < 0 || x >= bdims_.x || y >= bdims_.y || z >= bdims_.z)
                     ? nullptr
                     : table_[(size_t(z) * bdims_.y + y) * bdims_.x + x].load(std::memory_order_relaxed);
      }
      const bool edge = b->origin.x + kBrickSize > dims_.x || b->origin.y + kBrickSize > dims_.y ||
                        b->origin.z + kBrickSize > dims_.z;
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || keyDist2(k) > thr2_ || keyDist2(k) <= frozen2_ || keySite(k) == kNoSiteKey) continue;
        if (b->emitted.test(off) || b->exact.test(off)) continue;
        const Coord l = brickLocal(off);
        const Coord q = b->origin + l;
        const uint32_t site = keySite(k);
        const uint8_t region = regionOf(q);
        bool boundary = false;
        // Links are symmetric: the neighbour q + d offers to q along -d.
        for (const Link& d : linksFor(l, kNoDirection)) {
          BrickState* nb = nbr[d.brick];
          if (!nb) continue;
          const Coord n{q.x + d.x, q.y + d.y, q.z + d.z};
          if (edge && !grid_.contains(n)) continue;
          const uint64_t nk = nb->key[off + d.offset].load(std::memory_order_relaxed);
          if (nk == kUntouched || keySite(nk) == site || keySite(nk) == kNoSiteKey) continue;
          if (!stencil_.propagates(n) || (region_ && regionOf(n) != region)) continue;
          boundary = true;
          break;
        }
        if (boundary) checkVoxel({bi, uint16_t(off)}, q, k, block, tb);
      }
    }
  });
}

// Tries every site held within Chebyshev distance 2 of voxel v (key k); a better one is recorded as a correction.
void BandRun::checkVoxel(const VoxelRef& v, const Coord& q, uint64_t k, uint64_t* block, ThreadBuffers& tb) const {
  gatherBlock(q, block);
  uint64_t best = k;
  uint32_t last_site = keySite(k);
  for (int j = 0; j < 125; ++j) {
    const uint64_t nk = block[j];
    if (nk == kUntouched) continue;
    const uint32_t s = keySite(nk);
    if (s == last_site || s == keySite(best)) continue;
    last_site = s;
    const uint64_t cand = packKey(metric_.key2(s, q.x, q.y, q.z), kNoDirection, s);
    if (cand < best) best = cand;
  }
  if (keySite(best) != keySite(k)) tb.corrections.push_back({v, best});
}

// The second-ring correction (exact mode). A voxel whose true closest site is held by none of its stencil
// neighbours sits where different sites meet; it tries every site held within Chebyshev distance 2. Which voxels
// are checked is decided by the field alone, so the result does not depend on thread timing:
//   * the first round of a segment checks every voxel of the segment at a site boundary (scanCandidates);
//   * later rounds check only boundary voxels within distance 2 of a voxel changed since the last round.
FrontList BandRun::correct(bool first_round) {
  if (first_round) {
    collectPending();
    scanAndCheck();
  } else {
    std::vector<VoxelRef> dirty;
    for (auto& tb : buffers_) {
      dirty.insert(dirty.end(), tb.dirty.begin(), tb.dirty.end());
      tb.dirty.clear();
    }
    // Visits the touched voxels within distance 2 of every changed voxel (each changed voxel once).
    auto aroundDirty = [&](auto&& visit) {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, dirty.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          if (stoppingAt(i, 16)) return;
          const BrickState* db = table_[dirty[i].brick].load(std::memory_order_relaxed);
          const Coord c = db->origin + brickLocal(dirty[i].offset);
          for (int dz = -2; dz <= 2; ++dz)
            for (int dy = -2; dy <= 2; ++dy)
              for (int dx = -2; dx <= 2; ++dx) {
                const Coord q{c.x + dx, c.y + dy, c.z + dz};
                if (!grid_.contains(q)) continue;
                const uint32_t bi = brickIndex(q.x, q.y, q.z);
                BrickState* b = table_[bi].load(std::memory_order_relaxed);
                if (!b) continue;
                const int off = brickOffset(q.x & 7, q.y & 7, q.z & 7);
                if (b->key[off].load(std::memory_order_relaxed) != kUntouched) visit(b, bi, off, q);
              }
        }
      });
    };
    for (const VoxelRef& d : dirty)
      table_[d.brick].load(std::memory_order_relaxed)->dirty.clear(d.offset);
    // Check each candidate once, as it is claimed (queued), without listing them: corrections are only recorded
    // here and applied after the round, so which thread checks a voxel does not matter.
    aroundDirty([&](BrickState* b, uint32_t bi, int off, const Coord& q) {
      if (!b->queued.set(off)) return;
      const uint64_t k = b->key[off].load(std::memory_order_relaxed);
      if (keyDist2(k) > thr2_ || keyDist2(k) <= frozen2_ || keySite(k) == kNoSiteKey || b->exact.test(off) ||
          !isBoundary(q, k))
        return;
      uint64_t block[125];
      checkVoxel({bi, uint16_t(off)}, q, k, block, buffers_.local());
    });
    aroundDirty([&](BrickState* b, uint32_t, int off, const Coord&) {
      if (b->queued.test(off)) b->queued.clear(off);
    });
  }
  FrontList front;
  for (auto& tb : buffers_) {
    for (const auto& [v, key] : tb.corrections) {
      BrickState* b = table_[v.brick].load(std::memory_order_relaxed);
      b->key[v.offset].store(key, std::memory_order_relaxed);
      ++corrections_;
      if (b->dirty.set(v.offset)) tb.dirty.push_back(v);
      if (stencil_.propagates(b->origin + brickLocal(v.offset)))
        front.push_back({v.brick, v.offset, uint8_t(kNoDirection), keySite(key)});
    }
    tb.corrections.clear();
  }
  return front;
}

// Keys of the 5^3 block centred on q (index (dz+2)*25 + (dy+2)*5 + (dx+2)); kUntouched outside the grid, in
// another region, untouched, or holding no site.
void BandRun::gatherBlock(const Coord& q, uint64_t* block) const {
  // Per axis: is the coordinate inside the grid, which of the (at most two) bricks holds it, its local index.
  int bsel[3][5], local[3][5];
  bool valid[3][5];
  const int qc[3] = {q.x, q.y, q.z}, dims[3] = {dims_.x, dims_.y, dims_.z};
  int b0[3];
  for (int a = 0; a < 3; ++a) {
    b0[a] = (qc[a] - 2) >> kBrickLog2;
    for (int i = 0; i < 5; ++i) {
      const int c = qc[a] + i - 2;
      valid[a][i] = c >= 0 && c < dims[a];
      bsel[a][i] = (c >> kBrickLog2) - b0[a];
      local[a][i] = c & 7;
    }
  }
  const int bdims[3] = {bdims_.x, bdims_.y, bdims_.z};
  BrickState* bricks[2][2][2];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int c = 0; c < 2; ++c) {
        const int bx = b0[0] + c, by = b0[1] + b, bz = b0[2] + a;
        bricks[a][b][c] = (bx >= 0 && by >= 0 && bz >= 0 && bx < bdims[0] && by < bdims[1] && bz < bdims[2])
                              ? table_[(size_t(bz) * bdims[1] + by) * bdims[0] + bx].load(std::memory_order_relaxed)
                              : nullptr;
      }
  const uint8_t region = regionOf(q);
  int j = 0;
  for (int iz = 0; iz < 5; ++iz)
    for (int iy = 0; iy < 5; ++iy) {
      if (!valid[2][iz] || !valid[1][iy]) {
        for (int ix = 0; ix < 5; ++ix) block[j++] = kUntouched;
        continue;
      }
      BrickState* const* row = bricks[bsel[2][iz]][bsel[1][iy]];
      const int yz = (local[1][iy] << 3) | local[2][iz];
      for (int ix = 0; ix < 5; ++ix, ++j) {
        BrickState* nb = row[bsel[0][ix]];
        uint64_t nk = kUntouched;
        if (valid[0][ix] && nb) {
          nk = nb->key[(local[0][ix] << 6) | yz].load(std::memory_order_relaxed);
          if (keySite(nk) == kNoSiteKey ||
              (region_ && regionOf({q.x + ix - 2, q.y + iy - 2, q.z + iz - 2}) != region))
            nk = kUntouched;
        }
        block[j] = nk;
      }
    }
}

// After the last segment's bricks are built nothing reads the band again: free it before the consumer builds its
// output, so the two never peak together, and hand large amounts back (freed in the worker threads' malloc arenas,
// they would otherwise stay in this process).
void BandRun::releaseBricks() {
  std::atomic<size_t> freed{0};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, table_.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    size_t count = 0;
    for (size_t i = r.begin(); i != r.end(); ++i)
      if (BrickState* b = table_[i].exchange(nullptr, std::memory_order_relaxed)) delete b, ++count;
    freed += count;
  });
  // Worth a trim (a few ms) only when it hands back a sizeable amount, and not on the way out of a stopped run: the
  // next run of this process reuses the pages anyway.
  if (freed * sizeof(BrickState) >= (size_t(64) << 20) && !stopping()) ::malloc_trim(0);
}

// Merges the bricks that got their first unemitted voxel into pending_bricks_, kept sorted by brick index. (Millions
// of bricks on large grids: sorted in parallel, and stoppable.)
void BandRun::collectPending() {
  for (auto& tb : buffers_) {
    pending_bricks_.insert(pending_bricks_.end(), tb.pending.begin(), tb.pending.end());
    tb.pending.clear();
  }
  if (!runInterruptible(opt_.interrupter, [&] { tbb::parallel_sort(pending_bricks_.begin(), pending_bricks_.end()); }))
    return;  // stopping() says so from now on
  pending_bricks_.erase(std::unique(pending_bricks_.begin(), pending_bricks_.end()), pending_bricks_.end());
}

// Voxels admitted beyond the previous threshold but not yet delivered start the new segment's lifespan clock.
void BandRun::rearmLifespans() {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pending_bricks_.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 64)) return;
      BrickState* b = table_[pending_bricks_[i]].load(std::memory_order_relaxed);
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || b->emitted.test(off)) continue;
        b->expiry[off].store(expiryFor(keyDist2(k)), std::memory_order_relaxed);
      }
    }
  });
}

// Delivers every touched voxel within the threshold not delivered before, as one callback or (max_chunk_bricks) in
// chunks. Returns whether this was the last segment: the limit was reached, or nothing was deferred and no admitted
// voxel waits beyond the threshold.
bool BandRun::emitSegment(int index, double lower_vox, double upper_vox, bool nothing_deferred, SegmentStats& stats) {
  collectPending();
  const double h = grid_.voxelSize();
  const size_t n = pending_bricks_.size();
  // Pass 1: which pending bricks deliver voxels now, and which keep voxels for later segments. The output is then
  // built in chunks of pending bricks (sorted by index, which is (z, y, x) order of their origins). In the last
  // segment each chunk's engine bricks are freed as soon as it is built, so the output grows while the engine state
  // shrinks instead of the two peaking together.
  std::vector<uint32_t> slot(n, 0);  // 1 + position in the segment's output, or 0
  std::vector<uint8_t> keep(n, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stoppingAt(i, 64)) return;
      BrickState* b = table_[pending_bricks_[i]].load(std::memory_order_relaxed);
      for (int off = 0; off < kBrickVoxels && !(slot[i] && keep[i]); ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        if (k == kUntouched || b->emitted.test(off)) continue;
        if (keyDist2(k) > thr2_) keep[i] = 1;
        else slot[i] = 1;
      }
    }
  });
  if (stopping()) return true;
  uint32_t count = 0;
  for (uint32_t& s : slot) s = s ? ++count : 0;
  bool waiting = false;
  for (uint8_t kept : keep) waiting |= kept != 0;
  const bool last = thr_is_limit_ || (nothing_deferred && !waiting);
  const bool triangles = seeds_.kind == SiteKind::kTriangle;
  auto piece = [&](bool complete) {
    SegmentBricks p;
    p.index = index;
    p.lower_world = lower_vox * h;
    p.upper_world = upper_vox * h;
    p.last = last && complete;
    p.complete = complete;
    return p;
  };
  // Ranges [c0, c1) of pending bricks holding at most `per_chunk` output bricks each, built and handed over in turn.
  const size_t per_chunk = opt_.max_chunk_bricks ? opt_.max_chunk_bricks : std::max<size_t>(count, 1);
  constexpr size_t kBuildBricks = 8192;  // whole segments are built this many pending bricks at a time
  SegmentBricks whole = piece(true);
  whole.bricks.reserve(opt_.max_chunk_bricks ? 0 : count);
  std::vector<Brick> part;
  size_t freed_bytes = 0;
  uint32_t base = 0;  // output bricks before c0
  for (size_t c0 = 0; c0 < n || (c0 == 0 && n == 0);) {
    if (stopping()) return true;
    size_t c1 = c0, outs = 0;
    while (c1 < n && outs < per_chunk && c1 - c0 < kBuildBricks) outs += slot[c1++] != 0;
    part.assign(outs, Brick{});
    buildChunk(c0, c1, slot, keep, base, triangles, part);
    if (last) {
      for (size_t i = c0; i < c1; ++i) delete table_[pending_bricks_[i]].exchange(nullptr, std::memory_order_relaxed);
      freed_bytes += (c1 - c0) * sizeof(BrickState);
      if (freed_bytes >= (size_t(64) << 20) && c1 < n) {
        ::malloc_trim(0);  // the freed bricks' pages back before the next chunk's output (the last: below)
        freed_bytes = 0;
      }
    }
    for (const Brick& b : part) stats.voxels += b.mask.count();
    stats.bricks += int64_t(part.size());
    base += uint32_t(outs);
    const bool done = c1 >= n;
    if (opt_.max_chunk_bricks) {
      if (stopping()) return true;
      SegmentBricks p = piece(done);
      p.bricks = std::move(part);
      if (cb_) cb_(std::move(p));
    } else {
      whole.bricks.insert(whole.bricks.end(), part.begin(), part.end());
    }
    if (done) break;
    c0 = c1;
  }
  std::vector<Brick>().swap(part);
  if (last) releaseBricks();
  size_t w = 0;
  for (size_t i = 0; i < n; ++i)
    if (keep[i]) pending_bricks_[w++] = pending_bricks_[i];
  pending_bricks_.resize(w);
  if (!opt_.max_chunk_bricks && cb_ && !stopping()) cb_(std::move(whole));
  return last;
}

// The closest-feature id of a delivered voxel holding `site` (see Seeds::FeatureKind).
int64_t BandRun::closestFeature(uint32_t site, const Coord& voxel) const {
  if (seeds_.feature_kind == Seeds::FeatureKind::kSiteVoxel) {
    if (site == kNoSite) return grid_.denseIndex(voxel);  // inside the seed volume: its own feature
    const Vec3d& p = seeds_.points[site];
    const Coord o = seeds_.site_offset;
    return grid_.denseIndex({int(std::lround(p.x)) - o.x, int(std::lround(p.y)) - o.y, int(std::lround(p.z)) - o.z});
  }
  if (site == kNoSite) return -1;
  return seeds_.site_feature.empty() ? int64_t(site) : int64_t(seeds_.site_feature[site]);
}

// Builds the output bricks of pending bricks [c0, c1) into `out` (out[slot - 1 - base]) and marks them delivered.
void BandRun::buildChunk(size_t c0, size_t c1, const std::vector<uint32_t>& slot, const std::vector<uint8_t>& keep,
                         uint32_t base, bool triangles, std::vector<Brick>& out) {
  const double h = grid_.voxelSize();
  tbb::parallel_for(tbb::blocked_range<size_t>(c0, c1, 16), [&](const tbb::blocked_range<size_t>& r) {
    uint32_t sites[kBrickVoxels];
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (stopping()) return;  // per brick: a mesh's winding-number sign can take milliseconds a brick
      BrickState* b = table_[pending_bricks_[i]].load(std::memory_order_relaxed);
      if (!keep[i]) b->pending.store(false, std::memory_order_relaxed);
      if (!slot[i]) continue;
      Brick& brick = out[slot[i] - 1 - base];
      brick.origin = b->origin;
      if (opt_.closest_features) brick.closest.assign(kBrickVoxels, -1);
      for (int off = 0; off < kBrickVoxels; ++off) {
        const uint64_t k = b->key[off].load(std::memory_order_relaxed);
        sites[off] = kNoSite;
        if (k == kUntouched || keyDist2(k) > thr2_) continue;
        if (b->emitted.test(off)) continue;
        const Coord c = b->origin + brickLocal(off);
        const uint32_t s = keySite(k);
        sites[off] = s == kNoSiteKey ? kNoSite : s;
        // Triangle sites: the key's float squared distance is the exact one rounded to 24 bits, so its root is within
        // an ulp of the output's float (a second point–triangle test per voxel would buy nothing). Points are cheap.
        const double d2 = triangles ? double(keyDist2(k)) : metric_.dist2(s, c.x, c.y, c.z);
        brick.values[off] = float(std::sqrt(d2) * h);
        brick.mask.set(off);
        if (opt_.closest_features) brick.closest[off] = closestFeature(sites[off], c);
      }
      for (size_t w = 0; w < brick.mask.words.size(); ++w)
        b->emitted.words[w].fetch_or(brick.mask.words[w], std::memory_order_relaxed);
      if (seeds_.sign) seeds_.sign(brick, sites);
    }
  });
}

EngineResult BandRun::run() {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  EngineResult result;
  correcting_ = opt_.mode == PropagationMode::kExact && opt_.second_ring.value_or(seeds_.kind == SiteKind::kPoint);

  const bool segmented = segment_vox_ > 0;
  auto upperOf = [&](int i) {
    double u = segmented ? (i + 1) * segment_vox_ : INFINITY;
    return std::min(u, limit_vox_);
  };
  auto gatherFront = [&]() {
    FrontList front;
    if (stopping()) return front;  // the run ends: no need to copy the partial buffers
    size_t n = 0;
    for (auto& tb : buffers_) n += tb.next.size();
    front.reserve(n);
    for (auto& tb : buffers_) {
      if (!appendPolled(front, tb.next)) return FrontList();
      // A large buffer is given back rather than kept for the next step: the initial band's front can be tens of
      // MB, and later fronts are mostly much smaller (regrowing costs little next to the pushes that fill it).
      if (tb.next.capacity() > 65536) FrontList().swap(tb.next);
      tb.next.clear();
    }
    // The next front is usually about this one's size: one buffer of that size per thread instead of a chain of
    // doublings, whose freed links would stay behind as heap holes.
    const size_t share = n / std::max<size_t>(1, buffers_.size()) + 4096;
    for (auto& tb : buffers_) tb.next.reserve(share);
    // Snapshot each changed voxel's site as of the end of the step: the next step offers exactly these.
    tbb::parallel_for(tbb::blocked_range<size_t>(0, front.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        if (stoppingAt(i, 4096)) return;
        BrickState* b = table_[front[i].brick].load(std::memory_order_relaxed);
        const uint64_t k = b->key[front[i].offset].load(std::memory_order_relaxed);
        b->listed.clear(front[i].offset);
        front[i].site = keySite(k);
        front[i].dir = uint8_t(keyDir(k));
      }
    });
    return front;
  };

  // Moves the threads' held-back offers into deferred_; false when the run must stop.
  auto collectDeferred = [&]() {
    size_t n = deferred_.size();
    for (auto& tb : buffers_) n += tb.deferred.size();
    deferred_.reserve(n);
    for (auto& tb : buffers_) {
      if (!appendPolled(deferred_, tb.deferred)) return false;
      tb.deferred.clear();
    }
    return true;
  };
  // Held-back offers (this step's and earlier ones), deduplicated, as the next front.
  auto takeDeferred = [&]() {
    if (!collectDeferred()) return FrontList();
    auto order = [](const FrontEntry& a, const FrontEntry& b) {
      return std::tie(a.brick, a.offset, a.site) < std::tie(b.brick, b.offset, b.site);
    };
    auto same = [](const FrontEntry& a, const FrontEntry& b) {
      return a.brick == b.brick && a.offset == b.offset && a.site == b.site;
    };
    if (!runInterruptible(opt_.interrupter, [&] { tbb::parallel_sort(deferred_.begin(), deferred_.end(), order); }))
      return FrontList();  // stopping() says so from now on
    deferred_.erase(std::unique(deferred_.begin(), deferred_.end(), same), deferred_.end());
    FrontList f;
    f.swap(deferred_);
    return f;
  };

  // Exact mode only: the paper's band keeps the paper's order (slices would also delay voxels past a lifespan
  // counted from the segment start).
  bucket_vox_ =
      opt_.mode != PropagationMode::kExact || seeds_.siteCount() < kBucketMinSites ? 0.0
      : seeds_.kind == SiteKind::kTriangle                                         ? kTriangleBucketVoxels
                                                                                   : kBucketVoxels;
  insertBand();
  const bool push_band = seeds_.band_exact;  // first step from the band list, in segment 0 (below)
  FrontList front;
  auto releaseBand = [&] {
    if (owned_band_) std::vector<BandVoxel>().swap(*owned_band_);
  };
  if (!push_band) {
    releaseBand();
    front = gatherFront();
  }

  for (int seg = 0;; ++seg) {
    const auto ts = Clock::now();
    SegmentStats stats;
    stats.index = seg;
    const double lower = seg == 0 ? 0.0 : upperOf(seg - 1);
    const double upper = upperOf(seg);
    stats.lower_world = lower * grid_.voxelSize();
    stats.upper_world = upper * grid_.voxelSize();
    thr_is_limit_ = upper >= limit_vox_;
    thr2_ = std::isfinite(upper) ? float(upper * upper) : INFINITY;
    // Offers are admitted up to the current slice (the whole segment without buckets) plus the slack.
    double slice_upper = bucket_vox_ > 0 ? std::min(upper, lower + bucket_vox_) : upper;
    auto admitUpTo = [&](double u) {
      // A slice whose admission would reach the limit's is the limit's: nothing beyond it is held back.
      const double limit_admit = limit_vox_ + kLimitSlackVoxels;
      const bool at_limit = u >= limit_vox_ || u + kAdmitSlackVoxels >= limit_admit;
      const double admit = at_limit ? limit_admit : u + kAdmitSlackVoxels;
      admit2_ = std::isfinite(admit) ? float(admit * admit) : INFINITY;
      defer_ = !at_limit;
      if (at_limit) slice_upper = upper;
    };
    admitUpTo(slice_upper);
    segment_start_step_ = step_;
    lower_vox_ = lower;
    if (seg > 0 && use_lifespan_) rearmLifespans();
    collect_dirty_ = false;
    // The outer boundary of the finished region seeds this segment: every offer held back, replayed with the site
    // it offered then (the voxel may hold a better one for itself now, but not for its neighbours).
    if (seg > 0) front = takeDeferred();
    if (seg == 0 && push_band && !stopping()) {
      ++step_;
      ++stats.steps;
      stepFromBand();
      releaseBand();
      front = gatherFront();
    }
    for (;;) {
      if (stopping()) {
        result.interrupted = true;
        break;
      }
      if (front.empty() && slice_upper < upper) {
        front = takeDeferred();
        if (front.empty()) {
          slice_upper = upper;  // nothing held back: the segment is done
        } else {
          slice_upper = std::min(upper, slice_upper + bucket_vox_);
          admitUpTo(slice_upper);
          continue;
        }
      }
      if (front.empty()) {
        if (!correcting_) break;
        front = correct(!collect_dirty_);
        collect_dirty_ = true;
        if (front.empty()) break;
      }
      if (++step_ >= kMaxSteps) throw std::runtime_error("distband engine: step limit exceeded");
      ++stats.steps;
      step(front);
      front = gatherFront();
    }
    if (result.interrupted) break;
    collectDeferred();  // false only when the run stops, which the next line sees
    if (stopping()) {
      result.interrupted = true;
      break;
    }
    stats.seconds = std::chrono::duration<double>(Clock::now() - ts).count();
    const bool last = emitSegment(seg, lower, upper, deferred_.empty(), stats);
    if (stopping()) {
      result.interrupted = true;
      break;
    }
    frozen2_ = thr2_;
    result.voxels += stats.voxels;
    result.segments.push_back(stats);
    if (last) break;
  }
  result.steps = step_;
  result.corrections = corrections_;
  for (auto& tb : buffers_) {
    result.updates += tb.updates;
    result.bricks_allocated += tb.bricks;
  }
  result.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return result;
}

}  // namespace

namespace {

EngineResult runEngine(const Grid& grid, const Seeds& seeds, const EngineOptions& options,
                       const SegmentCallback& on_segment, std::vector<BandVoxel>* owned_band) {
  if (std::string e = validateOptions(grid, options); !e.empty()) throw std::invalid_argument(e);
  if (seeds.region && seeds.region->size() != size_t(grid.voxelCount()))
    throw std::invalid_argument("seeds.region must hold one label per grid voxel");
  EngineResult result;
  auto body = [&] {
    std::optional<BandRun> run;
    run.emplace(grid, seeds, options, on_segment, owned_band);
    result = run->run();
    const auto t0 = std::chrono::steady_clock::now();
    run.reset();
    result.release_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  runWithThreads(options.threads, body);
  return result;
}

}  // namespace

EngineResult computeDistanceField(const Grid& grid, const Seeds& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment) {
  return runEngine(grid, seeds, options, on_segment, nullptr);
}

EngineResult computeDistanceField(const Grid& grid, Seeds&& seeds, const EngineOptions& options,
                                  const SegmentCallback& on_segment) {
  Seeds owned = std::move(seeds);
  return runEngine(grid, owned, options, on_segment, &owned.band);
}

}  // namespace distband
