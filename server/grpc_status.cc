#include "server/grpc_status.h"

namespace distband {

grpc::StatusCode toGrpcCode(Status::Code code) {
  switch (code) {
    case Status::Code::kOk: return grpc::StatusCode::OK;
    case Status::Code::kInvalidArgument: return grpc::StatusCode::INVALID_ARGUMENT;
    case Status::Code::kNotFound: return grpc::StatusCode::NOT_FOUND;
    case Status::Code::kResourceExhausted: return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case Status::Code::kCancelled: return grpc::StatusCode::CANCELLED;
    case Status::Code::kDeadlineExceeded: return grpc::StatusCode::DEADLINE_EXCEEDED;
    case Status::Code::kUnavailable: return grpc::StatusCode::UNAVAILABLE;
    case Status::Code::kUnauthenticated: return grpc::StatusCode::UNAUTHENTICATED;
    case Status::Code::kIoError:  // the server opens no file because of a request: a failure of its own
    case Status::Code::kInternal: return grpc::StatusCode::INTERNAL;
  }
  return grpc::StatusCode::INTERNAL;
}

Status::Code fromGrpcCode(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return Status::Code::kOk;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE:
    case grpc::StatusCode::FAILED_PRECONDITION: return Status::Code::kInvalidArgument;
    case grpc::StatusCode::NOT_FOUND: return Status::Code::kNotFound;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return Status::Code::kResourceExhausted;
    case grpc::StatusCode::CANCELLED: return Status::Code::kCancelled;
    case grpc::StatusCode::DEADLINE_EXCEEDED: return Status::Code::kDeadlineExceeded;
    case grpc::StatusCode::UNAVAILABLE: return Status::Code::kUnavailable;
    case grpc::StatusCode::UNAUTHENTICATED:
    case grpc::StatusCode::PERMISSION_DENIED: return Status::Code::kUnauthenticated;
    default: return Status::Code::kInternal;
  }
}

}  // namespace distband
