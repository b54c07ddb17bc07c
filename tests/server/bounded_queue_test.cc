// BoundedQueue (server/bounded_queue.h): FIFO order, the byte bound (a push into a full queue waits for a pop; an
// item always enters an empty queue), pop's timeout, close() (drain, then kClosed; push refused; waiters woken) and
// abort() (queued items dropped). Blocking calls run on std::async threads and are checked with bounded waits: a
// call that should block is seen still pending after a short wait, one that should return is awaited for at most
// kGenerous (a hang fails the test instead of stalling it).
#include "server/bounded_queue.h"

#include <atomic>
#include <chrono>
#include <future>
#include <memory>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace distband {
namespace {

using namespace std::chrono_literals;
using Queue = BoundedQueue<int>;
using Clock = std::chrono::steady_clock;

constexpr auto kBlocked = 30ms;   // long enough for a call that should return at once to have returned
constexpr auto kGenerous = 2s;    // upper bound for a call that must return (only reached on failure)

// A call on another thread. If the test ends (or an assertion returns) while it is still blocked, the destructor
// closes the queue so that the thread, and the test, finish.
template <typename T, typename Q = Queue>
class Call {
 public:
  template <typename F>
  Call(Q& q, F f) : q_(q), f_(std::async(std::launch::async, std::move(f))) {}
  ~Call() {
    if (f_.valid() && f_.wait_for(0ms) != std::future_status::ready) q_.close();
  }
  /// Still blocked after `wait`.
  bool pending(std::chrono::milliseconds wait = kBlocked) { return f_.wait_for(wait) == std::future_status::timeout; }
  /// Returned within kGenerous.
  bool ready() { return f_.wait_for(kGenerous) == std::future_status::ready; }
  T get() { return f_.get(); }

 private:
  Q& q_;
  std::future<T> f_;
};

TEST(BoundedQueueTest, PopsInPushOrder) {
  Queue q(1000);
  for (int i = 1; i <= 5; ++i) ASSERT_TRUE(q.push(i, 10));
  for (int i = 1; i <= 5; ++i) {
    int v = 0;
    ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
    EXPECT_EQ(v, i);
  }
  int v = -1;
  EXPECT_EQ(q.pop(&v, 0ms), Queue::PopResult::kTimeout);
  EXPECT_EQ(v, -1) << "a timed-out pop must not write *out";
}

TEST(BoundedQueueTest, PopWaitsForItsTimeoutOnAnEmptyQueue) {
  Queue q(100);
  int v = 0;
  const auto start = Clock::now();
  EXPECT_EQ(q.pop(&v, 20ms), Queue::PopResult::kTimeout);
  EXPECT_GE(Clock::now() - start, 19ms);
}

TEST(BoundedQueueTest, WaitingPopReceivesAnItemPushedLater) {
  Queue q(100);
  Call<int> popped(q, [&] {
    int v = 0;
    return q.pop(&v, 5s) == Queue::PopResult::kItem ? v : -1;
  });
  EXPECT_TRUE(popped.pending());
  ASSERT_TRUE(q.push(42, 1));
  ASSERT_TRUE(popped.ready());
  EXPECT_EQ(popped.get(), 42);
}

TEST(BoundedQueueTest, MoveOnlyItems) {
  BoundedQueue<std::unique_ptr<int>> q(100);
  ASSERT_TRUE(q.push(std::make_unique<int>(7), 8));
  std::unique_ptr<int> out;
  ASSERT_EQ(q.pop(&out, 0ms), BoundedQueue<std::unique_ptr<int>>::PopResult::kItem);
  ASSERT_NE(out, nullptr);
  EXPECT_EQ(*out, 7);
}

TEST(BoundedQueueTest, FillsUpToCapacityWithoutBlocking) {
  Queue q(10);
  Call<bool> pushes(q, [&] { return q.push(1, 4) && q.push(2, 6); });
  ASSERT_TRUE(pushes.ready()) << "4 + 6 bytes fit a 10-byte queue";
  EXPECT_TRUE(pushes.get());
  q.close();  // nothing should be left blocked
}

TEST(BoundedQueueTest, ItemLargerThanCapacityEntersAnEmptyQueue) {
  Queue q(10);
  Call<bool> push(q, [&] { return q.push(1, 1000); });
  if (!push.ready()) {
    FAIL() << "push of an oversized item into an empty queue blocked";
  }
  EXPECT_TRUE(push.get());
  int v = 0;
  EXPECT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  EXPECT_EQ(v, 1);
}

TEST(BoundedQueueTest, PushIntoFullQueueBlocksUntilPop) {
  Queue q(10);
  ASSERT_TRUE(q.push(1, 6));
  ASSERT_TRUE(q.push(2, 4));  // exactly full
  Call<bool> third(q, [&] { return q.push(3, 1); });
  EXPECT_TRUE(third.pending()) << "push into a queue holding its capacity must wait";
  int v = 0;
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  EXPECT_EQ(v, 1);
  ASSERT_TRUE(third.ready()) << "a pop must wake the blocked producer";
  EXPECT_TRUE(third.get());
  for (int expected : {2, 3}) {
    ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
    EXPECT_EQ(v, expected);
  }
}

TEST(BoundedQueueTest, OversizedItemStillWaitsWhileTheQueueIsFull) {
  Queue q(10);
  ASSERT_TRUE(q.push(1, 10));
  Call<bool> big(q, [&] { return q.push(2, 50); });
  EXPECT_TRUE(big.pending()) << "only an empty queue admits an item of any size";
  int v = 0;
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  ASSERT_TRUE(big.ready());
  EXPECT_TRUE(big.get());
}

TEST(BoundedQueueTest, PopReturnsTheBytesOfThePoppedItem) {
  // After popping the 6-byte item only 4 bytes are held: a 6-byte push fits at once, then the queue is full again.
  Queue q(10);
  ASSERT_TRUE(q.push(1, 6));
  ASSERT_TRUE(q.push(2, 4));
  int v = 0;
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  Call<bool> refill(q, [&] { return q.push(3, 6); });
  ASSERT_TRUE(refill.ready());
  EXPECT_TRUE(refill.get());
  Call<bool> over(q, [&] { return q.push(4, 1); });
  EXPECT_TRUE(over.pending()) << "4 + 6 bytes held: the queue is full";
  q.close();
  ASSERT_TRUE(over.ready());
  EXPECT_FALSE(over.get());
}

TEST(BoundedQueueTest, CloseDrainsRemainingItemsThenReportsClosed) {
  Queue q(100);
  ASSERT_TRUE(q.push(1, 1));
  ASSERT_TRUE(q.push(2, 1));
  q.close();
  int v = 0;
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  EXPECT_EQ(v, 1);
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  EXPECT_EQ(v, 2);
  const auto start = Clock::now();
  EXPECT_EQ(q.pop(&v, 5s), Queue::PopResult::kClosed);
  EXPECT_LT(Clock::now() - start, 1s) << "a closed, empty queue must not wait for the timeout";
}

TEST(BoundedQueueTest, PushAfterCloseIsRefusedAndNotQueued) {
  Queue q(100);
  q.close();
  EXPECT_FALSE(q.push(1, 1));
  int v = 0;
  EXPECT_EQ(q.pop(&v, 0ms), Queue::PopResult::kClosed);
}

TEST(BoundedQueueTest, CloseWakesABlockedConsumer) {
  Queue q(100);
  Call<Queue::PopResult> popped(q, [&] {
    int v = 0;
    return q.pop(&v, 5s);
  });
  EXPECT_TRUE(popped.pending());
  q.close();
  ASSERT_TRUE(popped.ready());
  EXPECT_EQ(popped.get(), Queue::PopResult::kClosed);
}

TEST(BoundedQueueTest, CloseWakesABlockedProducerWhichFails) {
  Queue q(10);
  ASSERT_TRUE(q.push(1, 10));
  Call<bool> blocked(q, [&] { return q.push(2, 5); });
  EXPECT_TRUE(blocked.pending());
  q.close();
  ASSERT_TRUE(blocked.ready());
  EXPECT_FALSE(blocked.get());
  // The item queued before close() is still delivered; the refused one is not.
  int v = 0;
  ASSERT_EQ(q.pop(&v, 0ms), Queue::PopResult::kItem);
  EXPECT_EQ(v, 1);
  EXPECT_EQ(q.pop(&v, 0ms), Queue::PopResult::kClosed);
}

TEST(BoundedQueueTest, AbortDropsQueuedItemsAndRefusesPushes) {
  Queue q(100);
  ASSERT_TRUE(q.push(1, 1));
  ASSERT_TRUE(q.push(2, 1));
  q.abort();
  int v = 0;
  EXPECT_EQ(q.pop(&v, 0ms), Queue::PopResult::kClosed);
  EXPECT_FALSE(q.push(3, 1));
}

TEST(BoundedQueueTest, AbortFreesTheItemsMemoryAtOnce) {
  auto item = std::make_shared<int>(1);
  std::weak_ptr<int> watch = item;
  BoundedQueue<std::shared_ptr<int>> q(100);
  ASSERT_TRUE(q.push(std::move(item), 1));
  EXPECT_FALSE(watch.expired());
  q.abort();
  EXPECT_TRUE(watch.expired()) << "abort() must drop the queued items";
}

TEST(BoundedQueueTest, AbortWakesABlockedProducer) {
  Queue q(10);
  ASSERT_TRUE(q.push(1, 10));
  Call<bool> blocked(q, [&] { return q.push(2, 5); });
  EXPECT_TRUE(blocked.pending());
  q.abort();
  ASSERT_TRUE(blocked.ready());
  EXPECT_FALSE(blocked.get());
}

TEST(BoundedQueueTest, ManyProducersAndConsumersDeliverEveryItemOnce) {
  constexpr int kProducers = 4, kPerProducer = 500;
  Queue q(64);  // small: producers block often
  std::vector<std::thread> producers;
  for (int p = 0; p < kProducers; ++p)
    producers.emplace_back([&, p] {
      for (int i = 0; i < kPerProducer; ++i) ASSERT_TRUE(q.push(p * kPerProducer + i, 8));
    });
  std::vector<std::atomic<int>> seen(kProducers * kPerProducer);
  std::atomic<int> received{0};
  auto consume = [&] {
    int v = 0;
    for (;;) {
      const auto r = q.pop(&v, kGenerous);
      if (r != Queue::PopResult::kItem) {
        if (r == Queue::PopResult::kTimeout) q.abort();  // a stall: fail the producers instead of hanging them
        return r;
      }
      seen[v].fetch_add(1);
      received.fetch_add(1);
    }
  };
  Call<Queue::PopResult> c1(q, consume), c2(q, consume);
  for (auto& t : producers) t.join();
  q.close();
  ASSERT_TRUE(c1.ready());
  ASSERT_TRUE(c2.ready());
  EXPECT_EQ(c1.get(), Queue::PopResult::kClosed);
  EXPECT_EQ(c2.get(), Queue::PopResult::kClosed);
  EXPECT_EQ(received.load(), kProducers * kPerProducer);
  for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i].load(), 1) << "item " << i;
}

}  // namespace
}  // namespace distband
