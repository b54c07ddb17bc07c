#include "server/request_id.h"

#include <random>

#include <fmt/format.h>

namespace distband {

bool validRequestId(std::string_view id) {
  if (id.empty() || id.size() > kMaxRequestIdLength) return false;
  for (const char c : id) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                    c == '_' || c == ':' || c == '-';
    if (!ok) return false;
  }
  return true;
}

std::string generateRequestId() {
  thread_local std::mt19937_64 random{std::random_device{}()};
  return fmt::format("{:016x}{:016x}", random(), random());
}

RequestId takeRequestId(grpc::ServerContext* context) {
  RequestId r;
  const auto& metadata = context->client_metadata();
  const auto [first, last] = metadata.equal_range(kRequestIdHeader);
  if (first != last) {
    const std::string_view given(first->second.data(), first->second.size());
    if (std::next(first) == last && validRequestId(given)) r.id = std::string(given);
    else r.replaced = true;
  }
  if (r.id.empty()) r.id = generateRequestId();
  context->AddInitialMetadata(kRequestIdHeader, r.id);
  return r;
}

}  // namespace distband
