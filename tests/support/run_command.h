// runCommand: runs a shell command and returns its standard output and exit status (-1 when it could not run or did
// not exit normally). For tests and benches that start the project's binaries as real processes; append " 2>&1" to
// the command to capture standard error too. Header-only.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>
#include <utility>

namespace distband {

inline std::pair<std::string, int> runCommand(const std::string& cmd) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return {"", -1};
  std::array<char, 4096> buf{};
  size_t got;
  while ((got = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), got);
  const int status = ::pclose(p);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

}  // namespace distband
