#include "client/progress.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

namespace distband {
namespace {

double megabytes(uint64_t bytes) { return double(bytes) / 1e6; }

// "950", "12.3k", "4.56M", "1.2G".
std::string compactCount(int64_t n) {
  if (n < 1000) return fmt::format("{}", n);
  if (n < 1000000) return fmt::format("{:.3g}k", n / 1e3);
  if (n < 1000000000) return fmt::format("{:.3g}M", n / 1e6);
  return fmt::format("{:.3g}G", n / 1e9);
}

int initialEstimate(double limit, double segment_length) {
  if (!(segment_length > 0) || !std::isfinite(segment_length)) return std::isfinite(limit) ? 1 : 0;
  if (!std::isfinite(limit) || !(limit > 0)) return 0;
  const double n = std::ceil(limit / segment_length - 1e-9);
  return n > 1e6 ? 0 : std::max(1, int(n));
}

}  // namespace

std::string formatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  if (seconds < 60) return fmt::format("{:.1f}s", seconds);
  const int64_t s = int64_t(std::llround(seconds));
  if (s < 3600) return fmt::format("{}:{:02}", s / 60, s % 60);
  return fmt::format("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60);
}

ProgressDisplay::ProgressDisplay(ProgressOptions options) : options_(std::move(options)) {
  mode_ = options_.mode;
  if (!options_.out) mode_ = ProgressMode::kQuiet;
  if (mode_ == ProgressMode::kAuto)
    mode_ = ::isatty(fileno(options_.out)) ? ProgressMode::kTerminal : ProgressMode::kPlain;
  options_.bar_width = std::clamp(options_.bar_width, 0, 200);
  estimate_ = initialEstimate(options_.limit_world, options_.segment_length_world);
  start_ = now();
}

ProgressDisplay::~ProgressDisplay() {
  if (line_open_ && options_.out) {
    std::fputc('\n', options_.out);
    std::fflush(options_.out);
  }
}

double ProgressDisplay::now() const {
  if (options_.clock) return options_.clock();
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

SegmentProgress ProgressDisplay::summarize(const SegmentBricks& segment, uint64_t bytes) {
  SegmentProgress p;
  p.index = segment.index;
  p.lower_world = segment.lower_world;
  p.upper_world = segment.upper_world;
  p.bricks = int64_t(segment.bricks.size());
  for (const Brick& b : segment.bricks) p.voxels += b.mask.count();
  p.bytes = bytes;
  p.last = segment.last;
  return p;
}

void ProgressDisplay::print(const std::string& line) {
  std::fwrite(line.data(), 1, line.size(), options_.out);
  std::fflush(options_.out);
}

void ProgressDisplay::onData(int64_t bricks, int64_t voxels, uint64_t bytes) {
  if (finished_) return;
  pending_bricks_ += std::max<int64_t>(0, bricks);
  pending_voxels_ += std::max<int64_t>(0, voxels);
  pending_bytes_ += bytes;
  if (mode_ != ProgressMode::kTerminal) return;
  const double t = now();
  if (last_redraw_ < 0 || t - last_redraw_ >= options_.redraw_interval_s) redraw(t);
}

void ProgressDisplay::onSegment(const SegmentProgress& s) {
  if (finished_) return;
  pending_bricks_ = 0;
  pending_voxels_ = 0;
  pending_bytes_ = 0;
  bricks_ += s.bricks;
  voxels_ += s.voxels;
  bytes_ += s.bytes;
  done_ = std::max(done_, s.index + 1);
  if (s.last)
    estimate_ = done_;
  else if (estimate_ != 0 && done_ >= estimate_)
    estimate_ = done_ + 1;  // the estimate was short: at least one more is coming

  const double t = now();
  if (mode_ == ProgressMode::kTerminal) {
    redraw(t);
  } else if (mode_ == ProgressMode::kPlain) {
    const double elapsed = t - start_;
    std::string eta;
    if (const double left = etaSeconds(elapsed); !s.last && left >= 0)
      eta = fmt::format(", ETA {}{}", options_.expected_voxels > 0 ? "" : "~", formatDuration(left));
    if (options_.expected_voxels > 0) eta = fmt::format(", {:.0f}% of expected voxels", 100 * fraction()) + eta;
    print(fmt::format("segment {}/{} ({:.4g}, {:.4g}]: {} bricks, {} voxels, {:.2f} MB | total {} bricks, "
                      "{:.2f} MB, {} elapsed{}\n",
                      s.index + 1, estimate_ > 0 ? fmt::format("{}", estimate_) : std::string("?"),
                      s.lower_world, s.upper_world, s.bricks, s.voxels, megabytes(s.bytes), bricks_,
                      megabytes(bytes_), formatDuration(elapsed), eta));
  }
}

double ProgressDisplay::fraction() const {
  const bool all_done = estimate_ > 0 && done_ >= estimate_;
  if (options_.expected_voxels > 0)
    return all_done ? 1.0 : std::min(0.99, double(totalVoxels()) / double(options_.expected_voxels));
  return estimate_ > 0 ? std::min(1.0, double(done_) / estimate_) : 0.0;
}

double ProgressDisplay::etaSeconds(double elapsed) const {
  if (options_.expected_voxels > 0) {
    const int64_t got = totalVoxels();
    if (got <= 0 || got >= options_.expected_voxels) return -1;
    return elapsed * double(options_.expected_voxels - got) / double(got);
  }
  if (estimate_ > 0 && done_ > 0 && done_ < estimate_) return elapsed * (estimate_ - done_) / done_;
  return -1;
}

void ProgressDisplay::redraw(double t) {
  last_redraw_ = t;
  const double elapsed = t - start_;
  std::string bar;
  if (options_.bar_width > 0) {
    const double frac = fraction();
    const int filled = int(frac * options_.bar_width);
    bar.reserve(size_t(options_.bar_width) + 3);
    bar.push_back('[');
    bar.append(size_t(filled), '#');
    bar.append(size_t(options_.bar_width - filled), '-');
    bar.append("] ");
  }
  std::string eta;
  const bool all_done = estimate_ > 0 && done_ >= estimate_;
  if (!all_done && (totalVoxels() > 0 || done_ > 0)) {
    const double left = etaSeconds(elapsed);
    eta = fmt::format("  ETA {}{}", options_.expected_voxels > 0 || left < 0 ? "" : "~", formatDuration(left));
  }
  const std::string voxels = options_.expected_voxels > 0
                                 ? fmt::format("{}/{} voxels", compactCount(totalVoxels()),
                                               compactCount(options_.expected_voxels))
                                 : fmt::format("{} voxels", compactCount(totalVoxels()));
  print(fmt::format("\r{}segment {}/{}  {}  {:.1f} MB  {}{}\x1b[K", bar, done_,
                    estimate_ > 0 ? fmt::format("{}", estimate_) : std::string("?"), voxels,
                    megabytes(totalBytes()), formatDuration(elapsed), eta));
  line_open_ = true;
}

void ProgressDisplay::finish(bool ok, std::string_view message) {
  if (finished_) return;
  finished_ = true;
  if (mode_ == ProgressMode::kQuiet) return;
  const double t = now();
  if (mode_ == ProgressMode::kTerminal) {
    redraw(t);
    print("\n");
    line_open_ = false;
  }
  const double elapsed = t - start_;
  const double rate = elapsed > 0 ? megabytes(totalBytes()) / elapsed : 0;
  std::string line = ok ? "done" : "stopped";
  if (!message.empty()) line += fmt::format(" ({})", message);
  line += fmt::format(": {} segments, {} bricks, {} voxels, {:.2f} MB in {} ({:.1f} MB/s)\n", done_,
                      totalBricks(), totalVoxels(), megabytes(totalBytes()), formatDuration(elapsed), rate);
  print(line);
}

}  // namespace distband
