// Helpers shared by the benchmark programs: the median of timings, peak RSS of this process, running a child
// command, and reading the peak RSS that `/usr/bin/time -v` reports for it. Header-only; bench code only.
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace distband::bench {

/// Median of a non-empty sample (the mean of the middle two for an even count).
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// Peak resident set size of this process so far, in MiB (ru_maxrss is in KiB on Linux).
inline double peakRssMb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

/// Runs a shell command, returning its stdout and exit status (-1 if it could not run or did not exit).
inline std::pair<std::string, int> runCommand(const std::string& cmd) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return {"", -1};
  std::array<char, 4096> buf{};
  size_t got;
  while ((got = fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), got);
  const int status = pclose(p);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

/// The "Maximum resident set size" of `/usr/bin/time -v` output, in MiB.
inline std::optional<double> timeVPeakRssMb(const std::string& time_v_output) {
  constexpr const char* kKey = "Maximum resident set size (kbytes):";
  const size_t p = time_v_output.find(kKey);
  if (p == std::string::npos) return std::nullopt;
  return std::atof(time_v_output.c_str() + p + std::char_traits<char>::length(kKey)) / 1024.0;
}

}  // namespace distband::bench
