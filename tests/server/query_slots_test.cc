// QuerySlots (server/query_slots.h): at most N acquisitions hold a slot; another acquire() waits until a release,
// its wait budget, or abandon() returning true; active() counts the slots held. Waits are tens of milliseconds;
// calls expected to return are awaited for at most kGenerous.
#include "server/query_slots.h"

#include <atomic>
#include <chrono>
#include <future>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr auto kGenerous = 2s;
const std::function<bool()> kNever = [] { return false; };

TEST(QuerySlotsTest, AdmitsUpToTheSlotCountAtOnce) {
  QuerySlots slots(3);
  EXPECT_EQ(slots.active(), 0);
  for (int i = 1; i <= 3; ++i) {
    const auto start = Clock::now();
    ASSERT_TRUE(slots.acquire(1s, kNever)) << "slot " << i;
    EXPECT_LT(Clock::now() - start, 500ms) << "a free slot must be taken without waiting";
    EXPECT_EQ(slots.active(), i);
  }
  for (int i = 0; i < 3; ++i) slots.release();
  EXPECT_EQ(slots.active(), 0);
}

TEST(QuerySlotsTest, RefusesAfterTheWaitBudgetWhenAllSlotsAreHeld) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, kNever));
  const auto start = Clock::now();
  EXPECT_FALSE(slots.acquire(40ms, kNever));
  const auto waited = Clock::now() - start;
  EXPECT_GE(waited, 39ms) << "the refusal must come after the wait budget, not before";
  EXPECT_LT(waited, 1s);
  EXPECT_EQ(slots.active(), 1) << "a refused acquire takes no slot";
  slots.release();
}

TEST(QuerySlotsTest, ZeroWaitRefusesAtOnceWhenFull) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, kNever));
  const auto start = Clock::now();
  EXPECT_FALSE(slots.acquire(0ms, kNever));
  EXPECT_LT(Clock::now() - start, 100ms);
  slots.release();
}

TEST(QuerySlotsTest, ZeroSlotsAdmitNothing) {
  QuerySlots slots(0);
  EXPECT_FALSE(slots.acquire(20ms, kNever));
  EXPECT_EQ(slots.active(), 0);
}

TEST(QuerySlotsTest, ReleaseMakesTheSlotAvailableAgain) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, kNever));
  ASSERT_FALSE(slots.acquire(0ms, kNever));
  slots.release();
  EXPECT_EQ(slots.active(), 0);
  EXPECT_TRUE(slots.acquire(0ms, kNever));
  EXPECT_EQ(slots.active(), 1);
  slots.release();
}

TEST(QuerySlotsTest, AWaiterIsAdmittedWhenASlotIsReleased) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, kNever));
  const auto start = Clock::now();
  auto waiter = std::async(std::launch::async, [&] { return slots.acquire(5s, kNever); });
  EXPECT_EQ(waiter.wait_for(30ms), std::future_status::timeout) << "no slot is free: the waiter must wait";
  slots.release();
  ASSERT_EQ(waiter.wait_for(kGenerous), std::future_status::ready);
  EXPECT_TRUE(waiter.get());
  EXPECT_LT(Clock::now() - start, 1s) << "the release, not the 5 s budget, must end the wait";
  EXPECT_EQ(slots.active(), 1);
  slots.release();
}

TEST(QuerySlotsTest, AbandonEndsTheWaitWithoutASlot) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, kNever));
  std::atomic<bool> gone{false};
  std::atomic<int> polls{0};
  const auto start = Clock::now();
  auto waiter = std::async(std::launch::async, [&] {
    return slots.acquire(5s, [&] {
      polls.fetch_add(1);
      return gone.load();
    });
  });
  EXPECT_EQ(waiter.wait_for(30ms), std::future_status::timeout);
  EXPECT_GE(polls.load(), 1) << "abandon() is polled while waiting";
  gone = true;
  ASSERT_EQ(waiter.wait_for(kGenerous), std::future_status::ready);
  EXPECT_FALSE(waiter.get());
  EXPECT_LT(Clock::now() - start, 1s) << "abandon() is polled every 10 ms, not only at the end of the budget";
  EXPECT_EQ(slots.active(), 1);
  slots.release();
}

TEST(QuerySlotsTest, AbandonAlreadyTrueRefusesOnlyWhenItWouldWait) {
  QuerySlots slots(1);
  const std::function<bool()> gone = [] { return true; };
  EXPECT_TRUE(slots.acquire(1s, gone)) << "a free slot is taken: there is no wait to abandon";
  const auto start = Clock::now();
  EXPECT_FALSE(slots.acquire(1s, gone));
  EXPECT_LT(Clock::now() - start, 100ms);
  slots.release();
}

TEST(QuerySlotsTest, EmptyAbandonFunctionIsAllowed) {
  QuerySlots slots(1);
  ASSERT_TRUE(slots.acquire(0ms, {}));
  EXPECT_FALSE(slots.acquire(15ms, {}));
  slots.release();
}

TEST(QuerySlotsTest, NeverMoreHoldersThanSlotsUnderContention) {
  constexpr int kSlots = 2, kThreads = 8, kRounds = 100;
  QuerySlots slots(kSlots);
  std::atomic<int> holders{0}, max_holders{0}, admitted{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&] {
      for (int i = 0; i < kRounds; ++i) {
        if (!slots.acquire(kGenerous, kNever)) continue;
        const int now = holders.fetch_add(1) + 1;
        int seen = max_holders.load();
        while (now > seen && !max_holders.compare_exchange_weak(seen, now)) {
        }
        EXPECT_LE(slots.active(), kSlots);
        std::this_thread::yield();
        holders.fetch_sub(1);
        admitted.fetch_add(1);
        slots.release();
      }
    });
  for (auto& t : threads) t.join();
  EXPECT_LE(max_holders.load(), kSlots);
  EXPECT_GE(max_holders.load(), 1);
  EXPECT_EQ(admitted.load(), kThreads * kRounds) << "with a generous budget every acquire is admitted eventually";
  EXPECT_EQ(slots.active(), 0);
}

}  // namespace
}  // namespace distband
