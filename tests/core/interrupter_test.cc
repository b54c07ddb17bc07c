// Tests for core/interrupter.h and core/status.h.
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "core/interrupter.h"
#include "core/status.h"

namespace distband {
namespace {

TEST(StatusTest, OkAndErrorsCarryCodeAndMessage) {
  EXPECT_TRUE(Status().ok());
  EXPECT_EQ(Status::Ok().toString(), "OK");
  const Status s = Status::InvalidArgument("grid.resolution must be >= 2");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_EQ(s.toString(), "INVALID_ARGUMENT: grid.resolution must be >= 2");
  EXPECT_EQ(s.withPrefix("QueryRequest").message(), "QueryRequest: grid.resolution must be >= 2");
  EXPECT_TRUE(Status::Ok().withPrefix("x").ok());
  // An OK code never carries a message.
  EXPECT_EQ(Status(Status::Code::kOk, "ignored").message(), "");
}

TEST(InterrupterTest, NullAndFreshInterruptersRun) {
  EXPECT_FALSE(isInterrupted(nullptr));
  Interrupter i;
  EXPECT_FALSE(i.interrupted());
  EXPECT_TRUE(i.status().ok());
}

TEST(InterrupterTest, FirstCancelReasonWinsAndSticks) {
  Interrupter i;
  i.cancel(Status::Code::kUnavailable, "the server is shutting down");
  i.cancel(Status::Code::kCancelled, "later");
  EXPECT_TRUE(i.interrupted());
  EXPECT_TRUE(isInterrupted(&i));
  EXPECT_EQ(i.status().code(), Status::Code::kUnavailable);
  EXPECT_EQ(i.status().message(), "the server is shutting down");
}

TEST(InterrupterTest, DeadlineTripsOnTheNextPoll) {
  Interrupter i(Interrupter::Clock::now() + std::chrono::milliseconds(20));
  EXPECT_FALSE(i.interrupted());
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  EXPECT_TRUE(i.interrupted());
  EXPECT_EQ(i.status().code(), Status::Code::kDeadlineExceeded);
  i.cancel();  // too late: the deadline was the first reason
  EXPECT_EQ(i.status().code(), Status::Code::kDeadlineExceeded);
}

TEST(InterrupterTest, CancelFromAnotherThreadIsSeen) {
  Interrupter i;
  std::thread t([&] { i.cancel(); });
  t.join();
  EXPECT_TRUE(i.interrupted());
  EXPECT_EQ(i.status().code(), Status::Code::kCancelled);
}

}  // namespace
}  // namespace distband
