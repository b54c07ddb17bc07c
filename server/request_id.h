// Request ids: the `x-request-id` a call carries through the logs of the server, of a coordinator and of every
// replica it calls.
// Contract:
//   * A client may send `x-request-id` metadata. It is taken as the call's id when it is 1..128 characters of
//     [A-Za-z0-9._:-] and the call carries exactly one; anything else (absent, empty, too long, other characters,
//     repeated) is replaced by a generated id (32 lowercase hex digits, random), and the log line says so
//     (request_id_replaced=true). An id never reaches a log line or a reply in a form the rules above do not allow.
//   * The server echoes the id in the call's initial metadata (`x-request-id`), for every call of
//     distband.v1.DistanceField, refused ones included; a coordinator sends it to its replicas with every tile call
//     and upload, so their log lines carry it too.
// Thread-safe (the generator is per thread).
#pragma once

#include <string>
#include <string_view>

#include <grpcpp/server_context.h>

namespace distband {

inline constexpr char kRequestIdHeader[] = "x-request-id";
inline constexpr size_t kMaxRequestIdLength = 128;

/// Whether `id` may be used as given.
bool validRequestId(std::string_view id);
/// A fresh random id (32 hex digits).
std::string generateRequestId();

struct RequestId {
  std::string id;
  bool replaced = false;  ///< the client sent one that broke the rules
};

/// The call's id (the client's, or a generated one) — also added to the context's initial metadata.
RequestId takeRequestId(grpc::ServerContext* context);

}  // namespace distband
