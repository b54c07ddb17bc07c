#include "server/token_auth.h"

#include <openssl/crypto.h>
#include <openssl/sha.h>

#include <fstream>

#include <fmt/format.h>

namespace distband {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::string tokenProblem(std::string_view t) {
  if (t.size() < 16) return fmt::format("a token must have at least 16 characters (this one has {})", t.size());
  if (t.size() > 4096) return "a token must have at most 4096 characters";
  for (unsigned char c : t)
    if (c <= 0x20 || c >= 0x7f) return "a token must be printable ASCII without spaces";
  return {};
}

}  // namespace

Status TokenAuth::fromTokens(const std::vector<std::string>& tokens, std::unique_ptr<TokenAuth>* out) {
  auto auth = std::unique_ptr<TokenAuth>(new TokenAuth);
  for (size_t i = 0; i < tokens.size(); ++i) {
    if (std::string e = tokenProblem(tokens[i]); !e.empty())
      return Status::InvalidArgument(fmt::format("token {}: {}", i + 1, e));
    Digest d;
    SHA256(reinterpret_cast<const unsigned char*>(tokens[i].data()), tokens[i].size(), d.data());
    auth->digests_.push_back(d);
  }
  if (auth->digests_.empty()) return Status::InvalidArgument("no token given");
  *out = std::move(auth);
  return Status::Ok();
}

Status readTokenLines(const std::string& path, const char* flag, std::vector<TokenLine>* out) {
  std::ifstream in(path);
  if (!in) return Status::InvalidArgument(fmt::format("{} {}: cannot read the file", flag, path));
  out->clear();
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const std::string_view t = trim(line);
    if (t.empty() || t.front() == '#') continue;
    out->push_back({n, std::string(t)});
  }
  if (out->empty()) return Status::InvalidArgument(fmt::format("{} {}: the file holds no token", flag, path));
  return Status::Ok();
}

Status TokenAuth::load(const std::string& path, std::unique_ptr<TokenAuth>* out) {
  std::vector<TokenLine> lines;
  if (Status s = readTokenLines(path, "--auth-token-file", &lines); !s.ok()) return s;
  std::vector<std::string> tokens;
  for (TokenLine& l : lines) {
    if (std::string e = tokenProblem(l.token); !e.empty())
      return Status::InvalidArgument(fmt::format("--auth-token-file {} line {}: {}", path, l.line, e));
    tokens.push_back(std::move(l.token));
  }
  return fromTokens(tokens, out);
}

bool TokenAuth::acceptsHeader(std::string_view value) const {
  constexpr std::string_view kScheme = "Bearer ";
  if (value.size() < kScheme.size()) return false;
  // The scheme is case-insensitive (RFC 6750 / 7235).
  for (size_t i = 0; i < kScheme.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(value[i])) != std::tolower(static_cast<unsigned char>(kScheme[i])))
      return false;
  const std::string_view token = trim(value.substr(kScheme.size()));
  Digest d;
  SHA256(reinterpret_cast<const unsigned char*>(token.data()), token.size(), d.data());
  int matches = 0;
  for (const Digest& known : digests_) matches |= CRYPTO_memcmp(known.data(), d.data(), d.size()) == 0;
  return matches != 0;
}

Status TokenAuth::check(const grpc::ServerContext& context) const {
  const auto& md = context.client_metadata();
  const auto range = md.equal_range("authorization");
  if (range.first == range.second)
    return Status::Unauthenticated("this server requires 'authorization: Bearer <token>' metadata (none was sent)");
  if (std::next(range.first) != range.second)
    return Status::Unauthenticated("send exactly one 'authorization' metadata entry");
  const grpc::string_ref v = range.first->second;
  if (!acceptsHeader(std::string_view(v.data(), v.size())))
    return Status::Unauthenticated("the bearer token is not valid for this server");
  return Status::Ok();
}

}  // namespace distband
