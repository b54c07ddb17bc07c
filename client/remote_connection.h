// Connection flags shared by every service subcommand of `distband`: where the server is and how to talk to it.
//   --server HOST:PORT   --tls   --tls-ca FILE   --tls-cert FILE --tls-key FILE   --tls-server-name NAME
//   --token-file FILE    (or the DISTBAND_TOKEN environment variable)
// Contract: addConnectionFlags() only registers options; makeClientOptions() reads the named files (and the
// environment) and returns "" or a message naming the flag and the problem. TLS is used when --tls, --tls-ca or
// --tls-cert is given (--tls alone trusts the system's roots). A token from --token-file wins over DISTBAND_TOKEN;
// the file's first non-empty line is the token. Not synchronised.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "client/remote_client.h"

namespace distband {

struct ConnectionArgs {
  std::string server = "127.0.0.1:50051";
  bool tls = false;
  std::string tls_ca, tls_cert, tls_key, tls_server_name, token_file;
};

void addConnectionFlags(CLI::App* command, ConnectionArgs* args);
std::string makeClientOptions(const ConnectionArgs& args, RemoteClientOptions* out);

}  // namespace distband
