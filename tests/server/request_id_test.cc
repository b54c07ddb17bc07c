// Request ids: which client ids are kept, and what a generated one looks like.
#include "server/request_id.h"

#include <set>

#include <gtest/gtest.h>

namespace distband {
namespace {

TEST(RequestIdTest, KeepsBoundedIdsOfSafeCharacters) {
  EXPECT_TRUE(validRequestId("8f0c2b9e-4b1d-4a8e-9f5c-0d6e7a1b2c3d"));
  EXPECT_TRUE(validRequestId("00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01"));
  EXPECT_TRUE(validRequestId("job_17.step:3"));
  EXPECT_TRUE(validRequestId(std::string(kMaxRequestIdLength, 'a')));
}

TEST(RequestIdTest, RefusesEmptyLongAndUnsafeIds) {
  EXPECT_FALSE(validRequestId(""));
  EXPECT_FALSE(validRequestId(std::string(kMaxRequestIdLength + 1, 'a')));
  for (const char* bad : {"a b", "a\nb", "a\"b", "a\\b", "a'b", "a=b", "a/b", "{}", "a\x01", "\xc3\xa9t\xc3\xa9"})
    EXPECT_FALSE(validRequestId(bad)) << bad;
}

TEST(RequestIdTest, GeneratedIdsAreValidAndDistinct) {
  std::set<std::string> ids;
  for (int i = 0; i < 1000; ++i) {
    const std::string id = generateRequestId();
    EXPECT_EQ(id.size(), 32u);
    EXPECT_TRUE(validRequestId(id));
    ids.insert(id);
  }
  EXPECT_EQ(ids.size(), 1000u);
}

}  // namespace
}  // namespace distband
