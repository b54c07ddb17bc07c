// distband: the command-line entry point. All logic lives in the CLI libraries (client/cli.h) so tests can run it.
// Two binaries are built from this file:
//   * `distband`, the front binary: compute in-process, without the gRPC stack. Dynamic linking of gRPC, protobuf,
//     abseil and OpenSSL (~50 libraries) cost every `distband compute` ~10 ms before main; so the service
//     subcommands (query, upload, info, health, and `at --server`) are run by handing the whole command line,
//     unchanged, to `distband-remote` in the same directory (execv, as git runs its git-<command> helpers).
//   * `distband-remote` (DISTBAND_FULL_CLI): every subcommand, the service's included.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "client/batch_heap.h"
#include "client/cli.h"

namespace {

#if !defined(DISTBAND_FULL_CLI) && defined(DISTBAND_REMOTE_HELPER)
// Runs distband-remote with this process's arguments; returns only when that is impossible.
int runRemoteHelper(char** argv) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::filesystem::path helper = (ec ? std::filesystem::path(argv[0]) : self).parent_path() / DISTBAND_REMOTE_HELPER;
  ::execv(helper.c_str(), argv);
  std::cerr << "distband " << argv[1] << ": cannot run " << helper.string() << " (the service client, installed beside "
            << "distband): " << std::strerror(errno) << "\n";
  return distband::kExitFailure;
}

/// The service's commands, and `at --server ...` (`at` runs in-process otherwise).
bool isRemoteCommand(int argc, char** argv) {
  for (const distband::RemoteCommandName& r : distband::kRemoteCommands)
    if (std::strcmp(argv[1], r.name) == 0) return true;
  if (std::strcmp(argv[1], "at") != 0) return false;
  for (int i = 2; i < argc; ++i)
    if (std::strcmp(argv[i], "--server") == 0 || std::strncmp(argv[i], "--server=", 9) == 0) return true;
  return false;
}
#endif

}  // namespace

int main(int argc, char** argv) {
#if !defined(DISTBAND_FULL_CLI) && defined(DISTBAND_REMOTE_HELPER)
  if (argc > 1 && isRemoteCommand(argc, argv)) return runRemoteHelper(argv);
#endif
  // A batch command's malloc policy (client/batch_heap.h): large blocks from a heap that grows 64 MiB at a time on
  // huge pages (page faults cost ~12 µs each on virtual machines).
  distband::configureBatchHeap();
  distband::installInterruptHandler();
  const std::vector<std::string> args(argv + 1, argv + argc);
  const distband::CliContext context{std::cout, std::cerr, [] { return distband::interruptRequested(); }};
  return distband::runDistband(args, context);
}
