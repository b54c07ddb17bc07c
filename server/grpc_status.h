// The one place where core's Status codes become gRPC status codes (and back, for clients of the service).
// Contract: a user error (kInvalidArgument, kNotFound) is never INTERNAL; a server failure (kInternal) is never
// INVALID_ARGUMENT; budgets and limits are RESOURCE_EXHAUSTED. Messages pass through unchanged.
#pragma once

#include <grpcpp/support/status.h>

#include "core/status.h"

namespace distband {

grpc::StatusCode toGrpcCode(Status::Code code);
inline grpc::Status toGrpcStatus(const Status& s) {
  return s.ok() ? grpc::Status::OK : grpc::Status(toGrpcCode(s.code()), s.message());
}

Status::Code fromGrpcCode(grpc::StatusCode code);
inline Status fromGrpcStatus(const grpc::Status& s) {
  return s.ok() ? Status::Ok() : Status(fromGrpcCode(s.error_code()), s.error_message());
}

}  // namespace distband
