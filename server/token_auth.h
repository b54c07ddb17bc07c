// TokenAuth: bearer-token authentication of DistanceField calls (--auth-token-file).
// Contract:
//   * load() reads a file with one token a line (blank lines and lines starting with '#' are skipped; surrounding
//     whitespace is trimmed). Tokens must be 16..4096 printable ASCII characters without spaces; a file without
//     any token is an error. Errors name the file and the line, never a token.
//   * check() accepts a call whose metadata carries exactly one `authorization: Bearer <token>` naming a loaded
//     token, else UNAUTHENTICATED. Comparison is constant-time: every token is compared (as SHA-256 digests, so the
//     tokens' lengths do not leak either) without an early exit.
//   * The health service is not checked (probes carry no token); the server only calls check() from its own
//     handlers.
// Immutable after load(); thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <grpcpp/server_context.h>

#include "core/status.h"

namespace distband {

/// One token of a token file and the line it stands on.
struct TokenLine {
  int line = 0;
  std::string token;
};

/// The tokens of a file named by `flag` (--auth-token-file, --peer-token-file): one a line, surrounding whitespace
/// trimmed, blank lines and lines starting with '#' skipped. Errors (unreadable, no token) name the flag and the
/// file, never a token.
Status readTokenLines(const std::string& path, const char* flag, std::vector<TokenLine>* out);

class TokenAuth {
 public:
  static Status load(const std::string& path, std::unique_ptr<TokenAuth>* out);
  /// From tokens already in memory (tests).
  static Status fromTokens(const std::vector<std::string>& tokens, std::unique_ptr<TokenAuth>* out);

  Status check(const grpc::ServerContext& context) const;
  /// The same check on a header value ("Bearer <token>").
  bool acceptsHeader(std::string_view authorization) const;
  size_t size() const { return digests_.size(); }

 private:
  using Digest = std::array<uint8_t, 32>;
  std::vector<Digest> digests_;
};

}  // namespace distband
