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

// --deadline: the watch trips when the deadline passes, with kDeadlineExceeded (not the user's kCancelled), and runs
// on_stop once, so a command whose work does not poll the interrupter (a remote query) is stopped too.
TEST(InterruptWatchTest, ADeadlineTripsItAndRunsOnStopOnce) {
  std::atomic<int> stops{0};
  InterruptWatch watch(nullptr, Interrupter::Clock::now() + std::chrono::milliseconds(30), [&] { ++stops; });
  EXPECT_FALSE(watch.deadlinePassed());
  const auto t0 = std::chrono::steady_clock::now();
  while (stops.load() == 0 && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(5))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(30));  // more polls: on_stop must not run again
  EXPECT_EQ(stops.load(), 1);
  EXPECT_TRUE(watch.interrupter().interrupted());
  EXPECT_TRUE(watch.deadlinePassed());
}

TEST(InterruptWatchTest, AStopAskedBeforehandRunsOnStopAtOnce) {
  int stops = 0;
  InterruptWatch watch([] { return true; }, std::nullopt, [&] { ++stops; });
  EXPECT_EQ(stops, 1);
  EXPECT_FALSE(watch.deadlinePassed());
  EXPECT_EQ(watch.interrupter().status().code(), Status::Code::kCancelled);
}

}  // namespace
}  // namespace distband
