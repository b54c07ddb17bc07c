// Test support: what kind of build the tests run in, for the few latency bounds that only a Release build can hold.
// Contract: kSanitizedBuild is true under AddressSanitizer (clang or gcc), which CI's `scripts/test --sanitize` uses.
// In other builds the bounds are what they are given; under ASan they allow for its allocator, and the Release suite
// keeps the bounds themselves (bench/cancel_bench and bench/hostile_load measure them):
//   * latencyBoundMs(ms): ten times `ms` — ASan frees a large array in 100+ ms on the development VM (poisoning its
//     shadow), where Release takes under a millisecond;
//   * residentBoundBytes(bytes): plus ASan's quarantine (freed memory it keeps resident, 256 MiB by default) and its
//     shadow (a byte per 8).
#pragma once

namespace distband::testing {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kSanitizedBuild = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kSanitizedBuild = true;
#else
inline constexpr bool kSanitizedBuild = false;
#endif
#else
inline constexpr bool kSanitizedBuild = false;
#endif

inline constexpr double latencyBoundMs(double release_ms) { return kSanitizedBuild ? 10 * release_ms : release_ms; }

inline constexpr double residentBoundBytes(double release_bytes) {
  return kSanitizedBuild ? release_bytes * 1.125 + 256.0 * 1024 * 1024 : release_bytes;
}

}  // namespace distband::testing
