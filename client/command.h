// CliCommand: one `distband` subcommand, registered on the top-level CLI11 app.
// Contract: a register function (e.g. registerComputeCommand) adds a subcommand and its options to the app and
// returns the subcommand plus a `run` closure that reads the parsed options. runDistband() (client/cli.h) calls
// `run` of the subcommand the user chose, after parsing succeeded. Exit codes, shared by every subcommand:
//   0 success; 1 runtime failure (compute or write failed, or --deadline passed); 2 usage or input error (bad flags,
//   unreadable or malformed input files, bad dims); 130 interrupted (SIGINT).
// Commands write results/logs to `out` and diagnostics to `err`; they never call exit().
#pragma once

#include <functional>
#include <ostream>

#include <CLI/CLI.hpp>

namespace distband {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;
inline constexpr int kExitInterrupted = 130;

/// The service's subcommands (client/remote_commands.h), named here too so a `distband` built without them (the
/// front binary, which hands them to `distband-remote`) lists them in its help with the same words.
struct RemoteCommandName {
  const char* name;
  const char* description;
};
inline constexpr RemoteCommandName kRemoteCommands[] = {
    {"query", "Compute a distance field on a distband server and write it"},
    {"upload", "Upload a mesh or seed volume to a distband server's cache"},
    {"info", "Show a distband server's version, limits and options"},
    {"health", "grpc.health.v1 check of a distband server (exit 0 iff SERVING)"},
};

struct CliCommand {
  CLI::App* app = nullptr;    ///< the subcommand
  std::function<int()> run;   ///< runs it with the parsed options; returns the exit code
};

/// Everything a command may need from its environment (streams, the interrupt flag).
struct CliContext {
  std::ostream& out;
  std::ostream& err;
  std::function<bool()> interrupted;  ///< true once the user asked to stop (may be empty)
};

}  // namespace distband
