// GoogleTest predicates for core's Status: IsOk (success, else the status is printed) and IsError (the code, and a
// message that names what was wrong). Use as EXPECT_TRUE(IsOk(f())) << context; EXPECT_TRUE(IsError(f(), code, "x")).
#pragma once

#include <string>
#include <string_view>

#include <gtest/gtest.h>

#include "core/status.h"

namespace distband {

inline ::testing::AssertionResult IsOk(const Status& s) {
  if (s.ok()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << s.toString();
}

/// True when `s` failed with `code` and its message contains `names` (the field, file element or rule it names).
inline ::testing::AssertionResult IsError(const Status& s, Status::Code code, std::string_view names) {
  if (s.code() == code && s.message().find(names) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "expected " << Status::codeName(code) << " naming \"" << names << "\", got "
                                       << s.toString();
}

}  // namespace distband
