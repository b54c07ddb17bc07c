#include "client/interrupt_watch.h"

#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

namespace distband {
namespace {

// A stop asked before the watch exists must be seen even by a command that ends before any poll thread runs (a
// 32^3 compute finished inside the first poll period and ignored it: the flaky InterruptedRunWritesNothing).
TEST(InterruptWatchTest, AStopAskedBeforehandTripsAtOnce) {
  for (int i = 0; i < 100; ++i) {
    InterruptWatch watch([] { return true; });
    EXPECT_TRUE(watch.interrupter().interrupted());
  }
}

TEST(InterruptWatchTest, AStopAskedLaterTripsWithinAFewPolls) {
  std::atomic<bool> asked{false};
  InterruptWatch watch([&] { return asked.load(); });
  EXPECT_FALSE(watch.interrupter().interrupted());
  asked = true;
  const auto t0 = std::chrono::steady_clock::now();
  while (!watch.interrupter().interrupted() && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(5))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_TRUE(watch.interrupter().interrupted());
}

TEST(InterruptWatchTest, NoPredicateNeverTrips) {
  InterruptWatch watch(nullptr);
  std::this_thread::sleep_for(std::chrono::milliseconds(15));
  EXPECT_FALSE(watch.interrupter().interrupted());
}

}  // namespace
}  // namespace distband
