// SegmentMerger (server/segment_merger.h): the protocol's order across segments (a segment's SegmentDone after
// every tile finished it, later segments held and released in tile then arrival order), ties between tiles in every
// order, tiles whose band ends early or that had nothing to compute, empty segments, the buffer bound
// (RESOURCE_EXHAUSTED), replays of failed attempts (no brick twice, nothing lost), abort, the `last` flag and the
// summary. The sink records the merged stream; most tests compare it as a trace ("0:s1[2,3]" is tile 0's batch of
// segment 1 with bricks 2 and 3, "D1" the merged SegmentDone(1), "D1!" one marked last). A randomised test merges
// random tile streams in random interleavings, with failed attempts replayed, against a reference merge.
#include "server/segment_merger.h"

#include <algorithm>
#include <array>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

using Message = SegmentMerger::Message;

/// Brick `id`'s origin in the trace tests: (8 id, 0, 0).
v1::BrickData* addBrick(v1::BrickBatch* b, int x, int y, int z, size_t value_bytes) {
  v1::BrickData* d = b->add_bricks();
  d->set_x(x);
  d->set_y(y);
  d->set_z(z);
  d->set_mask(std::string(64, '\xff'));
  d->set_values(std::string(value_bytes, 'v'));
  return d;
}

Message batch(uint32_t segment, const std::vector<int>& ids, size_t value_bytes = 16) {
  auto m = std::make_unique<v1::QueryReply>();
  m->mutable_bricks()->set_segment(segment);
  for (int id : ids) addBrick(m->mutable_bricks(), 8 * id, 0, 0, value_bytes);
  return m;
}

uint64_t batchBytes(uint32_t segment, const std::vector<int>& ids) { return batch(segment, ids)->ByteSizeLong(); }

v1::SegmentDone done(uint32_t segment, bool last, uint64_t voxels = 0, uint64_t bricks = 0, double compute = 0) {
  v1::SegmentDone d;
  d.set_segment(segment);
  d.set_lower(segment * 1.0);
  d.set_upper(segment + 1.0);
  d.set_voxels(voxels);
  d.set_bricks(bricks);
  d.set_compute_seconds(compute);
  d.set_last(last);
  return d;
}

struct Emitted {
  bool segment_done = false;
  size_t tile = 0;  ///< of a batch
  v1::QueryReply message;
};

/// A merger whose sink records the merged stream.
class Merge {
 public:
  explicit Merge(size_t tiles, uint64_t buffer_bytes = uint64_t(1) << 20, double segment_length = 1.0,
                 double limit = 4.0)
      : merger({tiles, buffer_bytes, segment_length, limit, SegmentMerger::Clock::now()},
               SegmentMerger::Sink{[this](size_t tile, Message m) { out.push_back({false, tile, *m}); },
                                   [this](Message m) { out.push_back({true, 0, *m}); }}) {}

  void ok(size_t tile, Message m) { ASSERT_TRUE(merger.onBatch(tile, std::move(m)).ok()); }
  /// The merged stream so far, in the trace notation.
  std::string trace() const {
    std::string s;
    for (const Emitted& e : out) {
      if (!s.empty()) s += ' ';
      if (e.segment_done) {
        s += 'D';
        s += std::to_string(e.message.segment_done().segment());
        if (e.message.segment_done().last()) s += '!';
        continue;
      }
      s += std::to_string(e.tile);
      s += ":s";
      s += std::to_string(e.message.bricks().segment());
      s += '[';
      for (int i = 0; i < e.message.bricks().bricks_size(); ++i) {
        if (i > 0) s += ',';
        s += std::to_string(e.message.bricks().bricks(i).x() / 8);
      }
      s += ']';
    }
    return s;
  }
  std::vector<v1::SegmentDone> dones() const {
    std::vector<v1::SegmentDone> d;
    for (const Emitted& e : out)
      if (e.segment_done) d.push_back(e.message.segment_done());
    return d;
  }

  std::vector<Emitted> out;
  SegmentMerger merger;
};

TEST(SegmentMergerTest, OneTileIsForwardedAsItArrives) {
  Merge m(1);
  m.ok(0, batch(0, {1, 2}));
  m.ok(0, batch(0, {3}));
  m.merger.onSegmentDone(0, done(0, false, 7, 3));
  m.ok(0, batch(1, {1}));
  EXPECT_EQ(m.trace(), "0:s0[1,2] 0:s0[3] D0 0:s1[1]");
  EXPECT_FALSE(m.merger.complete());
  m.merger.onSegmentDone(0, done(1, true, 2, 1));
  EXPECT_EQ(m.trace(), "0:s0[1,2] 0:s0[3] D0 0:s1[1] D1!");
  EXPECT_TRUE(m.merger.complete());
  const auto d = m.dones();
  EXPECT_EQ(d[0].voxels(), 7u);
  EXPECT_EQ(d[0].bricks(), 3u);
  EXPECT_EQ(d[1].lower(), 1.0);
  EXPECT_EQ(d[1].upper(), 2.0);
}

TEST(SegmentMergerTest, ASegmentIsDoneOnceEveryTileHasFinishedIt) {
  Merge m(3);
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(2, batch(0, {20}));
  m.merger.onSegmentDone(2, done(0, false));
  EXPECT_EQ(m.trace(), "0:s0[1] 2:s0[20]") << "tile 1 has not finished segment 0";
  EXPECT_EQ(m.merger.mergingSegment(), 0u);
  m.ok(1, batch(0, {10}));
  EXPECT_EQ(m.trace(), "0:s0[1] 2:s0[20] 1:s0[10]");
  m.merger.onSegmentDone(1, done(0, false));
  EXPECT_EQ(m.trace(), "0:s0[1] 2:s0[20] 1:s0[10] D0");
  EXPECT_EQ(m.merger.mergingSegment(), 1u);
}

TEST(SegmentMergerTest, TilesFinishingASegmentInAnyOrderGiveTheSameStream) {
  std::vector<size_t> order = {0, 1, 2};
  int orders = 0;
  do {
    Merge m(3);
    for (size_t t : order) {
      m.ok(t, batch(0, {int(t)}));
      m.merger.onSegmentDone(t, done(0, true, 10 * (t + 1), t + 1, 0.5));
      if (t != order.back()) {
        EXPECT_TRUE(m.dones().empty()) << "after tile " << t;
      }
    }
    const auto d = m.dones();
    ASSERT_EQ(d.size(), 1u);
    EXPECT_EQ(m.out.back().segment_done, true) << "the SegmentDone comes after every tile's bricks";
    EXPECT_EQ(d[0].segment(), 0u);
    EXPECT_EQ(d[0].voxels(), 60u);
    EXPECT_EQ(d[0].bricks(), 6u);
    EXPECT_DOUBLE_EQ(d[0].compute_seconds(), 1.5);
    EXPECT_EQ(d[0].lower(), 0.0);
    EXPECT_EQ(d[0].upper(), 1.0);
    EXPECT_TRUE(d[0].last());
    EXPECT_TRUE(m.merger.complete());
    ++orders;
  } while (std::next_permutation(order.begin(), order.end()));
  EXPECT_EQ(orders, 6);
}

TEST(SegmentMergerTest, LaterSegmentsAreHeldUntilTheirSegmentIsMerged) {
  Merge m(2);
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(0, batch(1, {2}));
  m.ok(0, batch(1, {3}));
  EXPECT_EQ(m.trace(), "0:s0[1]");
  EXPECT_EQ(m.merger.heldBytes(), batchBytes(1, {2}) + batchBytes(1, {3}));
  m.ok(1, batch(0, {10}));
  m.merger.onSegmentDone(1, done(0, false));
  EXPECT_EQ(m.trace(), "0:s0[1] 1:s0[10] D0 0:s1[2] 0:s1[3]");
  EXPECT_EQ(m.merger.heldBytes(), 0u);
}

TEST(SegmentMergerTest, HeldBatchesGoInTileOrderThenArrivalOrderAndOnlyForTheirSegment) {
  Merge m(3);
  m.merger.onSegmentDone(2, done(0, false));
  m.ok(2, batch(1, {20}));
  m.ok(2, batch(1, {21}));
  m.merger.onSegmentDone(2, done(1, false));
  m.ok(2, batch(2, {22}));
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(0, batch(1, {1}));
  EXPECT_EQ(m.trace(), "");
  m.merger.onSegmentDone(1, done(0, false));
  EXPECT_EQ(m.trace(), "D0 0:s1[1] 2:s1[20] 2:s1[21]") << "segment 2's batch waits for segment 1";
  m.merger.onSegmentDone(0, done(1, true));
  m.merger.onSegmentDone(1, done(1, true));
  EXPECT_EQ(m.trace(), "D0 0:s1[1] 2:s1[20] 2:s1[21] D1 2:s2[22]");
  m.merger.onSegmentDone(2, done(2, true));
  EXPECT_EQ(m.trace(), "D0 0:s1[1] 2:s1[20] 2:s1[21] D1 2:s2[22] D2!");
}

TEST(SegmentMergerTest, ATileWhoseBandEndsEarlyCountsAsFinished) {
  Merge m(2);
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, true, 4));
  m.ok(1, batch(0, {10}));
  m.merger.onSegmentDone(1, done(0, false, 5));
  m.ok(1, batch(1, {11}));
  m.merger.onSegmentDone(1, done(1, false, 6));
  m.ok(1, batch(2, {12}));
  m.merger.onSegmentDone(1, done(2, true, 7));
  EXPECT_EQ(m.trace(), "0:s0[1] 1:s0[10] D0 1:s1[11] D1 1:s2[12] D2!");
  const auto d = m.dones();
  EXPECT_EQ(d[0].voxels(), 9u);
  EXPECT_EQ(d[1].voxels(), 6u) << "segments after tile 0's band ended count tile 1 alone";
  EXPECT_EQ(d[2].voxels(), 7u);
}

TEST(SegmentMergerTest, OnlyTheHighestLastSegmentOfAnyTileIsMarkedLast) {
  Merge m(2);
  // Tile 1's whole band (three segments) arrives while tile 0 is still on segment 0.
  m.merger.onSegmentDone(1, done(0, false));
  m.ok(1, batch(1, {11}));
  m.merger.onSegmentDone(1, done(1, false));
  m.ok(1, batch(2, {12}));
  m.merger.onSegmentDone(1, done(2, true));
  EXPECT_EQ(m.trace(), "");
  EXPECT_TRUE(m.merger.sawLastSegment(1));
  m.merger.onSegmentDone(0, done(0, true));
  EXPECT_EQ(m.trace(), "D0 1:s1[11] D1 1:s2[12] D2!");
  EXPECT_TRUE(m.merger.complete());
}

TEST(SegmentMergerTest, ATileWithNothingToComputeIsFinishedWhenItsCallEnds) {
  Merge m(2, uint64_t(1) << 20, 1.5, 4.0);
  m.merger.onTileFinished(0);
  EXPECT_EQ(m.trace(), "");
  m.ok(1, batch(0, {10}));
  v1::SegmentDone d1 = done(0, true, 5, 1);
  d1.set_upper(1.5);
  m.merger.onSegmentDone(1, d1);
  EXPECT_EQ(m.trace(), "1:s0[10] D0!");
  const auto d = m.dones();
  EXPECT_EQ(d[0].voxels(), 5u);
  EXPECT_EQ(d[0].upper(), 1.5) << "the range is the reporting tile's";
}

TEST(SegmentMergerTest, WhenNoTileHasAnythingToComputeOneEmptySegmentEndsTheStream) {
  // (segment length, limit) -> the empty segment 0's upper bound.
  using Case = std::tuple<double, double, double>;
  for (const auto& [length, limit, upper] : std::vector<Case>{{1.5, 4.0, 1.5}, {0.0, 4.0, 4.0}, {5.0, 4.0, 4.0}}) {
    Merge m(3, uint64_t(1) << 20, length, limit);
    for (size_t t = 0; t < 3; ++t) m.merger.onTileFinished(t);
    ASSERT_EQ(m.trace(), "D0!");
    const auto d = m.dones();
    EXPECT_EQ(d[0].lower(), 0.0);
    EXPECT_EQ(d[0].upper(), upper) << "segment length " << length << ", limit " << limit;
    EXPECT_EQ(d[0].voxels(), 0u);
    EXPECT_EQ(d[0].bricks(), 0u);
    EXPECT_TRUE(m.merger.complete());
  }
}

TEST(SegmentMergerTest, SegmentsWithoutBricksAreMergedLikeAnyOther) {
  Merge m(2);
  m.merger.onSegmentDone(0, done(0, false));
  m.merger.onSegmentDone(0, done(1, false));
  m.merger.onSegmentDone(0, done(2, true));
  m.merger.onSegmentDone(1, done(0, false));
  m.ok(1, batch(1, {11}));
  m.merger.onSegmentDone(1, done(1, false, 3));
  m.merger.onSegmentDone(1, done(2, true));
  EXPECT_EQ(m.trace(), "D0 1:s1[11] D1 D2!");
  EXPECT_EQ(m.dones()[1].voxels(), 3u);
}

TEST(SegmentMergerTest, HoldingMoreThanTheBufferBoundIsResourceExhausted) {
  const uint64_t one = batchBytes(1, {1});
  Merge m(2, 2 * one);
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(0, batch(1, {1}));
  m.ok(0, batch(1, {2}));  // exactly the bound
  EXPECT_EQ(m.merger.heldBytes(), 2 * one);
  const Status s = m.merger.onBatch(0, batch(1, {3}));
  EXPECT_EQ(s.code(), Status::Code::kResourceExhausted) << s.toString();
  EXPECT_NE(s.message().find("--tile-buffer-bytes"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("while segment 0 waits"), std::string::npos) << s.message();
  // The merge has failed: tile 1 finishing the segment sends nothing.
  m.merger.onSegmentDone(1, done(0, true));
  m.merger.onSegmentDone(0, done(1, true));
  EXPECT_EQ(m.trace(), "");
  EXPECT_FALSE(m.merger.complete());
  EXPECT_EQ(m.merger.heldBytes(), 0u);
}

TEST(SegmentMergerTest, TheBufferBoundCountsEveryTilesHeldBatches) {
  const uint64_t one = batchBytes(1, {1});
  Merge m(3, 2 * one);
  m.merger.onSegmentDone(0, done(0, false));
  m.merger.onSegmentDone(2, done(0, false));
  m.ok(0, batch(1, {1}));
  m.ok(2, batch(1, {2}));
  EXPECT_EQ(m.merger.onBatch(2, batch(1, {3})).code(), Status::Code::kResourceExhausted)
      << "each tile holds less than the bound, together they would pass it";
}

TEST(SegmentMergerTest, ReleasedBatchesMakeRoomAgain) {
  const uint64_t one = batchBytes(1, {1});
  Merge m(2, one);
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(0, batch(1, {1}));
  m.merger.onSegmentDone(1, done(0, false));
  EXPECT_EQ(m.merger.heldBytes(), 0u);
  m.merger.onSegmentDone(0, done(1, false));
  m.ok(0, batch(2, {2}));  // fits: segment 1's batch left the buffer
  m.merger.onSegmentDone(1, done(1, false));
  m.merger.onSegmentDone(0, done(2, true));
  m.merger.onSegmentDone(1, done(2, true));
  EXPECT_EQ(m.trace(), "D0 0:s1[1] D1 0:s2[2] D2!");
}

TEST(SegmentMergerTest, BatchesOfTheMergedSegmentAreNeverHeld) {
  Merge m(2, 0);
  m.ok(0, batch(0, {1, 2, 3}));
  m.ok(1, batch(0, {10}));
  EXPECT_EQ(m.trace(), "0:s0[1,2,3] 1:s0[10]");
  EXPECT_EQ(m.merger.heldBytes(), 0u);
}

TEST(SegmentMergerTest, AReplayForwardsOnlyBricksTheFailedAttemptHadNotSent) {
  Merge m(2);
  m.ok(0, batch(0, {1, 2}));
  m.ok(0, batch(0, {3}));
  EXPECT_FALSE(m.merger.everythingMerged(0));
  m.merger.onAttemptFailed(0);
  m.ok(0, batch(0, {1, 4}));
  m.ok(0, batch(0, {2, 3}));  // all sent already: no batch at all
  m.ok(0, batch(0, {5}));
  m.merger.onSegmentDone(0, done(0, true));
  m.merger.onSegmentDone(1, done(0, true));
  EXPECT_EQ(m.trace(), "0:s0[1,2] 0:s0[3] 0:s0[4] 0:s0[5] D0!");
}

TEST(SegmentMergerTest, AReplayDropsWhatTheFailedAttemptHeldAndKeepsWhatItFinished) {
  Merge m(2);
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, false, 4));
  m.ok(0, batch(1, {2}));
  m.ok(0, batch(1, {3}));
  EXPECT_GT(m.merger.heldBytes(), 0u);
  m.merger.onAttemptFailed(0);
  EXPECT_EQ(m.merger.heldBytes(), 0u) << "the replay brings segment 1 again";
  // Tile 0 finished segment 0 before failing: tile 1 finishing it merges it without waiting for the replay.
  m.ok(1, batch(0, {10}));
  m.merger.onSegmentDone(1, done(0, false, 5));
  EXPECT_EQ(m.trace(), "0:s0[1] 1:s0[10] D0");
  // The replay, from its start.
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, false, 4));
  m.ok(0, batch(1, {2}));
  m.ok(0, batch(1, {3}));
  m.merger.onSegmentDone(0, done(1, true, 2));
  m.merger.onSegmentDone(1, done(1, true, 1));
  EXPECT_EQ(m.trace(), "0:s0[1] 1:s0[10] D0 0:s1[2] 0:s1[3] D1!");
  const auto d = m.dones();
  EXPECT_EQ(d[0].voxels(), 9u);
  EXPECT_EQ(d[1].voxels(), 3u);
}

TEST(SegmentMergerTest, ATileIsFullyMergedOnceItsBandEndedAtOrBeforeTheMergedSegment) {
  Merge m(2);
  m.merger.onSegmentDone(0, done(0, false));
  EXPECT_FALSE(m.merger.sawLastSegment(0));
  m.merger.onSegmentDone(0, done(1, true));
  EXPECT_TRUE(m.merger.sawLastSegment(0));
  EXPECT_FALSE(m.merger.everythingMerged(0)) << "its segment 1 is not merged yet";
  m.merger.onSegmentDone(1, done(0, false));
  EXPECT_TRUE(m.merger.everythingMerged(0));
  EXPECT_FALSE(m.merger.everythingMerged(1));
  // Its call failing now loses nothing: the coordinator finishes it instead of replaying it.
  m.merger.onTileFinished(0);
  m.merger.onSegmentDone(1, done(1, true));
  EXPECT_EQ(m.trace(), "D0 D1!");
}

TEST(SegmentMergerTest, AbortStopsTheMergeMidStream) {
  Merge m(2);
  m.ok(0, batch(0, {1}));
  m.merger.onSegmentDone(0, done(0, false));
  m.ok(0, batch(1, {2}));
  m.merger.abort();
  EXPECT_EQ(m.merger.heldBytes(), 0u);
  EXPECT_TRUE(m.merger.onBatch(1, batch(0, {10})).ok());
  m.merger.onSegmentDone(1, done(0, true));
  m.merger.onTileFinished(1);
  EXPECT_EQ(m.trace(), "0:s0[1]");
  EXPECT_FALSE(m.merger.complete());
  v1::QuerySummary s;
  m.merger.summarize(&s);
  EXPECT_EQ(s.value_bytes(), 64u + 16u) << "what was forwarded before the abort";
  EXPECT_EQ(s.segments_size(), 0);
}

TEST(SegmentMergerTest, TheSummaryAddsUpTheTilesAndTheMergedSegments) {
  Merge m(2);
  m.ok(0, batch(0, {1, 2}, 8));
  m.merger.onSegmentDone(0, done(0, false, 10, 2, 0.25));
  m.ok(0, batch(1, {1}, 4));
  m.merger.onSegmentDone(0, done(1, true, 5, 1, 0.5));
  v1::QuerySummary t0;
  t0.set_steps(3);
  t0.set_seed_seconds(0.5);
  t0.set_compute_seconds(1.0);
  t0.add_segments()->set_steps(1);
  t0.add_segments()->set_steps(2);
  m.merger.onSummary(0, t0);
  m.ok(1, batch(0, {10}, 32));
  m.merger.onSegmentDone(1, done(0, true, 20, 1, 0.125));
  v1::QuerySummary t1;
  t1.set_steps(4);
  t1.set_seed_seconds(0.25);
  t1.set_compute_seconds(2.0);
  t1.add_segments()->set_steps(4);
  m.merger.onSummary(1, t1);
  ASSERT_TRUE(m.merger.complete());
  v1::QuerySummary s;
  m.merger.summarize(&s);
  EXPECT_EQ(s.voxels(), 35u);
  EXPECT_EQ(s.bricks(), 4u);
  EXPECT_EQ(s.value_bytes(), 4 * 64u + 2 * 8u + 4u + 32u);
  EXPECT_EQ(s.value_bytes(), m.merger.valueBytes());
  EXPECT_EQ(s.steps(), 7u);
  EXPECT_DOUBLE_EQ(s.seed_seconds(), 0.75);
  EXPECT_DOUBLE_EQ(s.compute_seconds(), 3.0);
  ASSERT_EQ(s.segments_size(), 2);
  EXPECT_EQ(s.segments(0).segment(), 0u);
  EXPECT_EQ(s.segments(0).voxels(), 30u);
  EXPECT_EQ(s.segments(0).bricks(), 3u);
  EXPECT_DOUBLE_EQ(s.segments(0).compute_seconds(), 0.375);
  EXPECT_EQ(s.segments(0).steps(), 5u);
  EXPECT_EQ(s.segments(0).lower(), 0.0);
  EXPECT_EQ(s.segments(0).upper(), 1.0);
  EXPECT_EQ(s.segments(1).voxels(), 5u);
  EXPECT_EQ(s.segments(1).steps(), 2u);
  EXPECT_GE(s.segments(1).sent_seconds(), s.segments(0).sent_seconds());
}

// ---------------------------------------------------------------------------------------------------------------
// Random tile streams, merged in random interleavings with random failed attempts, against a reference merge.

struct Event {
  enum Kind { kBatch, kSegmentDone } kind;
  uint32_t segment;
  std::vector<std::array<int, 3>> bricks;  ///< kBatch
  bool last = false;                       ///< kSegmentDone
  uint64_t voxels = 0;                     ///< kSegmentDone
};

/// A replica's stream for one tile: per segment its batches then its SegmentDone; the last one marked. Brick origins
/// carry the tile in z, so tiles never share one; within a tile a brick recurs in several segments (a brick's voxels
/// spread over segments), never twice in one.
std::vector<Event> randomStream(size_t tile, uint32_t segments, std::mt19937& rng) {
  std::vector<Event> events;
  for (uint32_t s = 0; s < segments; ++s) {
    std::vector<int> pool(12);
    for (int i = 0; i < 12; ++i) pool[i] = i;
    std::shuffle(pool.begin(), pool.end(), rng);
    const int bricks = std::uniform_int_distribution<int>(0, 10)(rng);
    int used = 0;
    while (used < bricks) {
      Event e{Event::kBatch, s, {}};
      const int n = std::min(bricks - used, std::uniform_int_distribution<int>(1, 4)(rng));
      for (int i = 0; i < n; ++i, ++used) e.bricks.push_back({8 * (pool[used] % 4), 8 * (pool[used] / 4), 8 * int(tile)});
      events.push_back(e);
    }
    Event d{Event::kSegmentDone, s, {}};
    d.last = s + 1 == segments;
    d.voxels = uint64_t(bricks);
    events.push_back(d);
  }
  return events;
}

TEST(SegmentMergerTest, RandomInterleavingsWithReplaysMatchAReferenceMerge) {
  for (uint32_t seed = 1; seed <= 1000; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::mt19937 rng(seed);
    const size_t tiles = std::uniform_int_distribution<size_t>(1, 6)(rng);
    std::vector<std::vector<Event>> streams(tiles);
    for (size_t t = 0; t < tiles; ++t)
      streams[t] = randomStream(t, std::uniform_int_distribution<uint32_t>(0, 5)(rng), rng);

    // Reference: every (segment, origin) once; the segments are 0 .. the highest any tile had (at least one).
    std::set<std::tuple<uint32_t, int, int, int>> expected;
    std::map<uint32_t, uint64_t> expected_voxels;
    uint32_t segments = 1;
    for (const auto& stream : streams)
      for (const Event& e : stream) {
        if (e.kind == Event::kBatch)
          for (const auto& b : e.bricks) expected.insert({e.segment, b[0], b[1], b[2]});
        else
          expected_voxels[e.segment] += e.voxels;
        segments = std::max(segments, e.segment + 1);
      }

    Merge m(tiles);
    std::vector<size_t> next(tiles, 0);
    std::vector<int> failures(tiles, 0);
    std::vector<bool> ended(tiles, false);
    size_t open = tiles;
    while (open > 0) {
      size_t t = std::uniform_int_distribution<size_t>(0, tiles - 1)(rng);
      while (ended[t]) t = (t + 1) % tiles;
      // An attempt fails now and then, at any point of its stream (before its call ends); the dispatcher then
      // finishes the tile if everything it had is merged, else replays it.
      if (failures[t] < 2 && std::uniform_int_distribution<int>(0, 15)(rng) == 0) {
        ++failures[t];
        if (m.merger.everythingMerged(t)) {
          m.merger.onTileFinished(t);
          ended[t] = true;
          --open;
        } else {
          m.merger.onAttemptFailed(t);
          next[t] = 0;
        }
        continue;
      }
      if (next[t] == streams[t].size()) {  // the call ends well
        m.merger.onTileFinished(t);
        ended[t] = true;
        --open;
        continue;
      }
      const Event& e = streams[t][next[t]++];
      if (e.kind == Event::kSegmentDone) {
        v1::SegmentDone d = done(e.segment, e.last, e.voxels, e.bricks.size());
        m.merger.onSegmentDone(t, d);
      } else {
        auto msg = std::make_unique<v1::QueryReply>();
        msg->mutable_bricks()->set_segment(e.segment);
        for (const auto& b : e.bricks) addBrick(msg->mutable_bricks(), b[0], b[1], b[2], 4);
        ASSERT_TRUE(m.merger.onBatch(t, std::move(msg)).ok());
      }
    }

    ASSERT_TRUE(m.merger.complete());
    EXPECT_EQ(m.merger.heldBytes(), 0u);
    std::set<std::tuple<uint32_t, int, int, int>> seen;
    uint32_t merged = 0;  // SegmentDones so far: the segment being merged
    for (const Emitted& e : m.out) {
      if (e.segment_done) {
        const v1::SegmentDone& d = e.message.segment_done();
        ASSERT_EQ(d.segment(), merged) << "SegmentDones in order, none missing";
        EXPECT_EQ(d.voxels(), expected_voxels[merged]) << "segment " << merged;
        EXPECT_EQ(d.last(), merged + 1 == segments) << "segment " << merged;
        ++merged;
        continue;
      }
      const v1::BrickBatch& b = e.message.bricks();
      ASSERT_EQ(b.segment(), merged) << "a brick comes after its segment's predecessors and before its SegmentDone";
      ASSERT_GT(b.bricks_size(), 0) << "no empty batch";
      for (const v1::BrickData& d : b.bricks()) {
        EXPECT_EQ(d.z(), 8 * int(e.tile)) << "forwarded as its own tile's";
        EXPECT_TRUE(seen.insert({b.segment(), d.x(), d.y(), d.z()}).second)
            << "brick " << d.x() << "," << d.y() << "," << d.z() << " of segment " << b.segment() << " twice";
      }
    }
    EXPECT_EQ(merged, segments);
    EXPECT_EQ(seen, expected) << "every brick of every segment, nothing more";
  }
}

}  // namespace
}  // namespace distband
