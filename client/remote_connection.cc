#include "client/remote_connection.h"

#include <cstdlib>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

namespace distband {
namespace {

std::string readFile(const std::string& path, const char* flag, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fmt::format("{} {}: cannot read the file", flag, path);
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return {};
}

std::string trimmed(std::string s) {
  const size_t b = s.find_first_not_of(" \t\r\n"), e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

}  // namespace

void addConnectionFlags(CLI::App* cmd, ConnectionArgs* a) {
  cmd->add_option("--server", a->server, "Server address HOST:PORT")->capture_default_str();
  cmd->add_flag("--tls", a->tls, "Connect with TLS, trusting the system's root certificates (see --tls-ca)");
  cmd->add_option("--tls-ca", a->tls_ca, "PEM CA bundle that signed the server's certificate (implies --tls)");
  cmd->add_option("--tls-cert", a->tls_cert, "PEM client certificate, for servers requiring mutual TLS (with --tls-key)");
  cmd->add_option("--tls-key", a->tls_key, "PEM private key of --tls-cert");
  cmd->add_option("--tls-server-name", a->tls_server_name,
                  "Name to check the server's certificate against (default: the --server host)");
  cmd->add_option("--token-file", a->token_file,
                  "File whose first line is the bearer token (default: the DISTBAND_TOKEN environment variable)");
}

std::string makeClientOptions(const ConnectionArgs& a, RemoteClientOptions* o) {
  if (a.server.empty()) return "--server must not be empty";
  if (a.tls_cert.empty() != a.tls_key.empty()) return "--tls-cert and --tls-key must be given together";
  o->tls = a.tls || !a.tls_ca.empty() || !a.tls_cert.empty() || !a.tls_server_name.empty();
  if (!a.tls_ca.empty())
    if (std::string e = readFile(a.tls_ca, "--tls-ca", &o->tls_root_ca_pem); !e.empty()) return e;
  if (!a.tls_cert.empty()) {
    if (std::string e = readFile(a.tls_cert, "--tls-cert", &o->tls_client_cert_pem); !e.empty()) return e;
    if (std::string e = readFile(a.tls_key, "--tls-key", &o->tls_client_key_pem); !e.empty()) return e;
  }
  o->tls_server_name = a.tls_server_name;
  if (!a.token_file.empty()) {
    std::string text;
    if (std::string e = readFile(a.token_file, "--token-file", &text); !e.empty()) return e;
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);)
      if (!(o->bearer_token = trimmed(line)).empty()) break;
    if (o->bearer_token.empty()) return fmt::format("--token-file {}: the file holds no token", a.token_file);
  } else if (const char* env = std::getenv("DISTBAND_TOKEN"); env && *env) {
    o->bearer_token = trimmed(env);
  }
  return {};
}

}  // namespace distband
