// SegmentMerger: a tiled query's per-tile streams merged into one stream in the protocol's order (nearest first).
// It holds exactly the merge state — per tile: the segments it finished, whether its band ended and where, the
// batches it sent ahead of the merged segment, the brick origins it forwarded of the merged segment; per query: the
// segment being merged, the bytes held, the merged SegmentDones and the tiles' summaries. No gRPC, no threads: the
// coordinator (server/tiled_query.h) feeds it each tile's messages and it hands the merged stream to a Sink.
// Contract:
//   * Segment s is merged until every tile has finished it: a tile's BrickBatch of s goes to the sink at once; the
//     merged SegmentDone(s) goes once every tile has sent SegmentDone(s) or is finished (its band ended with an
//     earlier segment, or it had nothing to compute). Its range is the first reporting tile's (tiles in index order),
//     else the plan's; its counts are the tiles' sums; `last` is set when every tile is finished and s is the
//     highest last segment of any tile.
//   * Batches of later segments are held and forwarded, tile by tile in index order and each tile's in arrival order,
//     right after the SegmentDone of the segment before theirs. Held bytes (ByteSizeLong per batch) stay within
//     Config::buffer_bytes: a batch that would pass it fails the merge with RESOURCE_EXHAUSTED.
//   * A tile whose attempt failed (onAttemptFailed) is replayed from its start: what it held is dropped, segments
//     already merged and those it had finished are skipped, and of the merged segment only bricks not yet forwarded
//     (recognised by origin) go to the sink. Replicas compute deterministically, so nothing is lost.
//   * After an error or abort() nothing more goes to the sink; summarize() still reports what was merged.
//   * The sink is called synchronously, in stream order, from within the call that made a message ready; it may
//     block (a full stream buffer then paces the merge).
// Not thread-safe: one caller at a time (TiledQuery calls it under its dispatcher's lock, server/tile_dispatcher.h).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <unordered_set>
#include <vector>

#include "core/status.h"
#include "distband/v1/distband.pb.h"
#include "server/query_stream.h"

namespace distband {

class SegmentMerger {
 public:
  using Message = QueryStream::Message;
  using Clock = QueryStream::Clock;

  struct Config {
    size_t tiles = 0;
    uint64_t buffer_bytes = 0;          ///< --tile-buffer-bytes: later segments' batches held at most
    double segment_length_world = 0;    ///< the plan's, for the range of a segment no tile reported (0: one segment)
    double limit_world = 0;
    Clock::time_point started{};        ///< SegmentTiming.sent_seconds counts from here
  };
  /// Where the merged stream goes, message by message.
  struct Sink {
    /// A BrickBatch of the merged segment from `tile` (the client's point ids are the caller's to restore).
    std::function<void(size_t tile, Message batch)> batch;
    std::function<void(Message segment_done)> segment_done;
  };

  SegmentMerger(Config config, Sink sink);

  /// A BrickBatch message of `tile`'s stream. RESOURCE_EXHAUSTED (naming --tile-buffer-bytes) when holding it would
  /// pass the buffer bound; the merge has then failed (as after abort()).
  Status onBatch(size_t tile, Message batch);
  void onSegmentDone(size_t tile, const v1::SegmentDone& done);
  void onSummary(size_t tile, const v1::QuerySummary& summary);
  /// `tile`'s call ended well or it had nothing to compute: it is finished, whichever segments it reported.
  void onTileFinished(size_t tile);
  /// `tile`'s attempt failed and it runs again from its start (see the contract).
  void onAttemptFailed(size_t tile);
  /// Nothing more goes to the sink; held batches are dropped.
  void abort();

  /// Whether `tile`'s stream so far ended its band (a SegmentDone with `last`).
  bool sawLastSegment(size_t tile) const;
  /// Whether everything `tile` has to deliver is merged: its band ended at or before the merged segment, so a
  /// failure of its call loses nothing.
  bool everythingMerged(size_t tile) const;
  /// The merged stream's last SegmentDone went to the sink.
  bool complete() const { return complete_; }
  /// The segment being merged.
  uint32_t mergingSegment() const { return merging_; }
  uint64_t heldBytes() const { return held_bytes_; }

  /// Totals of what was merged (voxels, bricks, value bytes), the tiles' summaries added up (steps, seed and compute
  /// seconds) and one SegmentTiming per merged segment.
  void summarize(v1::QuerySummary* summary) const;
  /// Bytes of BrickData values, masks and closest ids forwarded.
  uint64_t valueBytes() const { return value_bytes_; }

 private:
  struct Held {
    Message batch;
    uint64_t bytes;
  };
  struct TileState {
    uint32_t completed = 0;  ///< segments finished (their SegmentDone seen)
    bool finished = false;   ///< its band ended (last SegmentDone seen, or its call ended well)
    uint32_t last = 0;       ///< index of its last segment, when finished
    bool replaying = false;  ///< an attempt failed: skip bricks already forwarded
    std::map<uint32_t, std::vector<Held>> held;  ///< batches of segments after the merged one
    uint64_t held_bytes = 0;
    std::unordered_set<uint64_t> forwarded;      ///< brick origins of the merged segment already forwarded
    std::vector<v1::SegmentDone> segments;       ///< its SegmentDone per finished segment
    v1::QuerySummary summary;
  };

  void forward(size_t tile, Message batch);
  /// Sends the merged SegmentDone of every segment all tiles have finished, releasing the held batches of the next.
  void advance();

  const Config config_;
  const Sink sink_;
  std::vector<TileState> tiles_;
  uint32_t merging_ = 0;
  bool complete_ = false;
  bool stopped_ = false;  ///< failed or aborted
  uint64_t held_bytes_ = 0, value_bytes_ = 0;
  std::vector<v1::SegmentTiming> timings_;
};

}  // namespace distband
