// ProgressDisplay: shows a streamed distance-field query to the person waiting for it.
// Contract:
//   * On a terminal (mode kAuto and isatty(out), or kTerminal) it keeps one line redrawn in place ("\r" and
//     erase-to-end-of-line): a bar, segment i/n, voxels received (of those expected), MB, elapsed time and ETA.
//     It moves with every brick batch (onData(); redraws throttled to redraw_interval_s); onSegment() always
//     redraws.
//   * Otherwise (kPlain) it prints one plain log line per finished segment, and nothing for onData().
//     kQuiet prints nothing at all.
//   * With expected_voxels > 0 (the server's estimate, QueryHeader.expected_voxels) the bar is voxels received /
//     expected and ETA = elapsed * (expected - received) / received: voxels, not segments, measure the work (an
//     outer segment is a larger shell). The bar stops short of full until the last segment; when more voxels
//     arrive than expected the ETA is unknown ("?"). Without an estimate the bar counts segments: n =
//     ceil(limit / segment_length) (1 with a single segment, "?" without a finite limit), growing if more arrive,
//     ETA = elapsed * (n - done) / done, a lower bound (marked "~").
//   * Counts: onData() reports data of the segment in progress; onSegment() closes a segment with its own,
//     authoritative counts (replacing what onData() reported for it). MB are 10^6 bytes.
//   * finish() ends the display (newline on a terminal) with one summary line; later calls do nothing.
// Fed from core types only (SegmentBricks / counts): no gRPC here. Not thread-safe: call from one thread.
#pragma once

#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <string_view>

#include "core/brick.h"

namespace distband {

enum class ProgressMode {
  kAuto,      ///< kTerminal if the output is a terminal, else kPlain
  kTerminal,  ///< one redrawn line
  kPlain,     ///< one log line per segment
  kQuiet,     ///< nothing
};

struct ProgressOptions {
  ProgressMode mode = ProgressMode::kAuto;
  std::FILE* out = stderr;
  double limit_world = std::numeric_limits<double>::infinity();  ///< the query's distance limit
  double segment_length_world = 0;                                ///< 0: a single segment
  int64_t expected_voxels = 0;  ///< the voxels the query is expected to deliver; 0: unknown
  /// Monotonic clock in seconds; empty: std::chrono::steady_clock. Injected by tests.
  std::function<double()> clock;
  int bar_width = 24;
  double redraw_interval_s = 0.1;
};

/// One finished segment as the client saw it.
struct SegmentProgress {
  int index = 0;                         ///< 0-based segment number
  double lower_world = 0, upper_world = 0;
  int64_t bricks = 0;                    ///< brick messages received for this segment
  int64_t voxels = 0;                    ///< voxels delivered (mask bits set)
  uint64_t bytes = 0;                    ///< payload bytes received for this segment
  bool last = false;
};

class ProgressDisplay {
 public:
  explicit ProgressDisplay(ProgressOptions options);
  ~ProgressDisplay();  ///< finishes the line if finish() was not called (never prints a summary then)
  ProgressDisplay(const ProgressDisplay&) = delete;
  ProgressDisplay& operator=(const ProgressDisplay&) = delete;

  /// Counts a SegmentBricks' bricks and voxels (mask bits).
  static SegmentProgress summarize(const SegmentBricks& segment, uint64_t bytes);

  /// One brick batch of the segment in progress.
  void onData(int64_t bricks, int64_t voxels, uint64_t bytes);
  void onSegment(const SegmentProgress& segment);
  void onSegment(const SegmentBricks& segment, uint64_t bytes) { onSegment(summarize(segment, bytes)); }
  /// Ends the display with "done: ..." or, when ok is false, "stopped: ..."; a non-empty message is added in
  /// parentheses after the word.
  void finish(bool ok = true, std::string_view message = {});

  bool terminal() const { return mode_ == ProgressMode::kTerminal; }
  int estimatedSegments() const { return estimate_; }  ///< 0 when unknown
  int segmentsDone() const { return done_; }
  int64_t totalBricks() const { return bricks_ + pending_bricks_; }
  uint64_t totalBytes() const { return bytes_ + pending_bytes_; }
  int64_t totalVoxels() const { return voxels_ + pending_voxels_; }
  /// The bar's fraction in [0, 1] (see above).
  double fraction() const;
  /// Seconds left, or -1 when unknown.
  double etaSeconds(double elapsed) const;

 private:
  double now() const;
  void redraw(double t);
  void print(const std::string& line);

  ProgressOptions options_;
  ProgressMode mode_;
  double start_ = 0;
  double last_redraw_ = -1;
  int estimate_ = 0;
  int done_ = 0;
  int64_t bricks_ = 0, voxels_ = 0;
  uint64_t bytes_ = 0;
  int64_t pending_bricks_ = 0, pending_voxels_ = 0;
  uint64_t pending_bytes_ = 0;
  bool line_open_ = false;
  bool finished_ = false;
};

/// "12.3s", "4:05", "1:02:03" — compact durations for the display.
std::string formatDuration(double seconds);

}  // namespace distband
