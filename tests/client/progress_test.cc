// Tests for client/progress: the plain per-segment log lines (numbers, estimate, ETA), the redrawn terminal line,
// and the summary — with an injected clock and an in-memory stream.
#include "client/progress.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

/// An in-memory FILE (not a terminal), read back as a string.
class Capture {
 public:
  Capture() : file_(open_memstream(&buf_, &size_)) {}
  ~Capture() {
    std::fclose(file_);
    std::free(buf_);
  }
  std::FILE* file() const { return file_; }
  std::string text() {
    std::fflush(file_);
    return std::string(buf_, size_);
  }

 private:
  char* buf_ = nullptr;
  size_t size_ = 0;
  std::FILE* file_;
};

std::vector<std::string> lines(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start < s.size()) {
    const size_t end = s.find('\n', start);
    out.push_back(s.substr(start, end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return out;
}

SegmentProgress seg(int index, double lo, double hi, int64_t bricks, int64_t voxels, uint64_t bytes,
                    bool last = false) {
  SegmentProgress s;
  s.index = index;
  s.lower_world = lo;
  s.upper_world = hi;
  s.bricks = bricks;
  s.voxels = voxels;
  s.bytes = bytes;
  s.last = last;
  return s;
}

TEST(ProgressTest, PlainModePrintsOneLinePerSegmentWithTheNumbers) {
  Capture out;
  double t = 100;
  ProgressOptions o;
  o.out = out.file();  // kAuto on a memory stream (not a terminal): plain lines
  o.limit_world = 10;
  o.segment_length_world = 2.5;
  o.clock = [&t] { return t; };
  ProgressDisplay p(o);
  EXPECT_FALSE(p.terminal());
  EXPECT_EQ(p.estimatedSegments(), 4);

  t = 100.5;
  p.onData(4, 2048, 8000);  // mid-segment data: counted, not printed in plain mode
  EXPECT_EQ(p.totalBricks(), 4);
  EXPECT_EQ(p.totalBytes(), 8000u);
  EXPECT_EQ(out.text(), "");

  t = 101;
  p.onSegment(seg(0, 0, 2.5, 10, 2000, 20000));
  EXPECT_EQ(p.totalBricks(), 10);  // the segment's own counts replace the mid-segment ones
  t = 102;
  p.onSegment(seg(1, 2.5, 5, 30, 9000, 1500000));
  t = 104;
  p.onSegment(seg(2, 5, 7.5, 60, 20000, 3000000));
  t = 106;
  p.onSegment(seg(3, 7.5, 10, 100, 35000, 5000000));  // the estimate (4) was short: grows to 5
  EXPECT_EQ(p.estimatedSegments(), 5);
  t = 107;
  p.onSegment(seg(4, 10, 10, 1, 3, 2100, /*last=*/true));
  EXPECT_EQ(p.estimatedSegments(), 5);
  t = 108;
  p.finish();
  p.finish();  // idempotent
  p.onSegment(seg(5, 10, 10, 1, 1, 1));  // ignored after finish

  const std::vector<std::string> l = lines(out.text());
  ASSERT_EQ(l.size(), 6u) << out.text();
  EXPECT_EQ(l[0],
            "segment 1/4 (0, 2.5]: 10 bricks, 2000 voxels, 0.02 MB | total 10 bricks, 0.02 MB, 1.0s elapsed, "
            "ETA ~3.0s");
  EXPECT_EQ(l[1],
            "segment 2/4 (2.5, 5]: 30 bricks, 9000 voxels, 1.50 MB | total 40 bricks, 1.52 MB, 2.0s elapsed, "
            "ETA ~2.0s");
  EXPECT_EQ(l[2],
            "segment 3/4 (5, 7.5]: 60 bricks, 20000 voxels, 3.00 MB | total 100 bricks, 4.52 MB, 4.0s elapsed, "
            "ETA ~1.3s");
  EXPECT_EQ(l[3],
            "segment 4/5 (7.5, 10]: 100 bricks, 35000 voxels, 5.00 MB | total 200 bricks, 9.52 MB, 6.0s elapsed, "
            "ETA ~1.5s");
  EXPECT_EQ(l[4], "segment 5/5 (10, 10]: 1 bricks, 3 voxels, 0.00 MB | total 201 bricks, 9.52 MB, 7.0s elapsed");
  EXPECT_EQ(l[5], "done: 5 segments, 201 bricks, 66003 voxels, 9.52 MB in 8.0s (1.2 MB/s)");
}

TEST(ProgressTest, UnknownAndSingleSegmentEstimates) {
  {
    Capture out;
    ProgressOptions o;
    o.mode = ProgressMode::kPlain;
    o.out = out.file();
    o.segment_length_world = 1;  // no finite limit: the count is unknown
    o.clock = [] { return 0.0; };
    ProgressDisplay p(o);
    EXPECT_EQ(p.estimatedSegments(), 0);
    p.onSegment(seg(0, 0, 1, 2, 3, 4));
    EXPECT_EQ(lines(out.text()).at(0).rfind("segment 1/? (0, 1]: 2 bricks, 3 voxels", 0), 0u) << out.text();
    EXPECT_EQ(out.text().find("ETA"), std::string::npos);
  }
  {
    Capture out;
    ProgressOptions o;
    o.mode = ProgressMode::kPlain;
    o.out = out.file();
    o.limit_world = 5;  // a single segment up to the limit
    o.clock = [] { return 0.0; };
    ProgressDisplay p(o);
    EXPECT_EQ(p.estimatedSegments(), 1);
    p.onSegment(seg(0, 0, 5, 7, 8, 9, true));
    p.finish(false, "cancelled");
    const std::vector<std::string> l = lines(out.text());
    ASSERT_EQ(l.size(), 2u);
    EXPECT_EQ(l[0].rfind("segment 1/1 (0, 5]: 7 bricks", 0), 0u) << l[0];
    EXPECT_EQ(l[1].rfind("stopped (cancelled): 1 segments, 7 bricks, 8 voxels", 0), 0u) << l[1];
  }
}

TEST(ProgressTest, TerminalModeRedrawsOneLineAndThrottlesData) {
  Capture out;
  double t = 0;
  ProgressOptions o;
  o.mode = ProgressMode::kTerminal;
  o.out = out.file();
  o.limit_world = 4;
  o.segment_length_world = 1;
  o.bar_width = 8;
  o.clock = [&t] { return t; };
  ProgressDisplay p(o);
  EXPECT_TRUE(p.terminal());
  t = 0.01;
  p.onData(5, 2560, 1000000);  // first data: drawn
  t = 0.05;
  p.onData(5, 2560, 1000000);  // within the redraw interval: not drawn
  t = 2;
  p.onSegment(seg(0, 0, 1, 12, 100, 2500000));
  const std::string s = out.text();
  EXPECT_EQ(std::count(s.begin(), s.end(), '\r'), 2);
  EXPECT_EQ(s.find('\n'), std::string::npos);  // a single line, redrawn in place
  EXPECT_NE(s.find("\r[--------] segment 0/4  2.56k voxels  1.0 MB  0.0s  ETA ?\x1b[K"), std::string::npos) << s;
  EXPECT_NE(s.find("\r[##------] segment 1/4  100 voxels  2.5 MB  2.0s  ETA ~6.0s\x1b[K"), std::string::npos) << s;
  t = 3;
  p.finish();
  const std::string all = out.text();
  EXPECT_EQ(all.substr(all.size() - 1), "\n");
  const std::vector<std::string> l = lines(all);
  ASSERT_EQ(l.size(), 2u);
  EXPECT_EQ(l[1], "done: 1 segments, 12 bricks, 100 voxels, 2.50 MB in 3.0s (0.8 MB/s)");
}

// With the server's estimate the bar moves with every batch and the ETA follows voxels, not segments.
TEST(ProgressTest, ExpectedVoxelsDriveTheBarAndTheEtaPerBatch) {
  Capture out;
  double t = 0;
  ProgressOptions o;
  o.mode = ProgressMode::kTerminal;
  o.out = out.file();
  o.limit_world = 4;
  o.segment_length_world = 4;  // one segment: a segment count could not move the bar at all
  o.expected_voxels = 1000;
  o.bar_width = 10;
  o.redraw_interval_s = 0;
  o.clock = [&t] { return t; };
  ProgressDisplay p(o);
  t = 1;
  p.onData(3, 250, 1000);
  EXPECT_DOUBLE_EQ(p.fraction(), 0.25);
  EXPECT_DOUBLE_EQ(p.etaSeconds(1), 3.0);  // 750 voxels left at 250 a second
  t = 2;
  p.onData(3, 250, 1000);
  const std::string s = out.text();
  EXPECT_NE(s.find("\r[##--------] segment 0/1  250/1k voxels  0.0 MB  1.0s  ETA 3.0s\x1b[K"), std::string::npos) << s;
  EXPECT_NE(s.find("\r[#####-----] segment 0/1  500/1k voxels  0.0 MB  2.0s  ETA 2.0s\x1b[K"), std::string::npos) << s;
  p.onData(3, 600, 1000);  // more than expected: the bar waits short of full, the ETA is unknown
  EXPECT_DOUBLE_EQ(p.fraction(), 0.99);
  EXPECT_LT(p.etaSeconds(2), 0);
  p.onSegment(seg(0, 0, 4, 9, 1100, 3000, true));
  EXPECT_DOUBLE_EQ(p.fraction(), 1.0);
}

TEST(ProgressTest, QuietModePrintsNothing) {
  Capture out;
  ProgressOptions o;
  o.mode = ProgressMode::kQuiet;
  o.out = out.file();
  ProgressDisplay p(o);
  p.onData(1, 1, 2);
  p.onSegment(seg(0, 0, 1, 1, 1, 1, true));
  p.finish();
  EXPECT_EQ(out.text(), "");
  EXPECT_EQ(p.totalBricks(), 1);
}

TEST(ProgressTest, SummarizeCountsBricksAndMaskedVoxels) {
  SegmentBricks s;
  s.index = 3;
  s.lower_world = 1.5;
  s.upper_world = 2;
  s.last = true;
  s.bricks.resize(2);
  s.bricks[0].mask.set(0);
  s.bricks[0].mask.set(100);
  s.bricks[0].mask.set(511);
  for (int i = 0; i < kBrickVoxels; ++i) s.bricks[1].mask.set(i);
  const SegmentProgress p = ProgressDisplay::summarize(s, 4242);
  EXPECT_EQ(p.index, 3);
  EXPECT_EQ(p.lower_world, 1.5);
  EXPECT_EQ(p.upper_world, 2);
  EXPECT_EQ(p.bricks, 2);
  EXPECT_EQ(p.voxels, 515);
  EXPECT_EQ(p.bytes, 4242u);
  EXPECT_TRUE(p.last);
}

TEST(ProgressTest, FormatsDurations) {
  EXPECT_EQ(formatDuration(0), "0.0s");
  EXPECT_EQ(formatDuration(59.94), "59.9s");
  EXPECT_EQ(formatDuration(61), "1:01");
  EXPECT_EQ(formatDuration(3725), "1:02:05");
  EXPECT_EQ(formatDuration(-1), "?");
}

}  // namespace
}  // namespace distband
