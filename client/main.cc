// distband: the command-line entry point. All logic lives in distband_cli_lib (client/cli.h) so tests can run it.
#include <malloc.h>

#include <iostream>
#include <string>
#include <vector>

#include "client/cli.h"

int main(int argc, char** argv) {
  // Grow malloc's heaps 64 MiB at a time and keep that much free at their tops: a command allocates and frees its
  // mesh, seeds and bricks in quick succession, and with glibc's default (grow and trim to the byte) each round
  // faults its pages in afresh. Untouched padding costs address space, not memory (peak RSS: unchanged at
  // armadillo 256^3, +3 % at 512^3); it cut armadillo 256^3's page faults by 20 % and its whole process by ~0.09 s
  // (bench/whole_process_bench, docs/benchmarks.md).
  mallopt(M_TOP_PAD, 64 << 20);
  distband::installInterruptHandler();
  const std::vector<std::string> args(argv + 1, argv + argc);
  const distband::CliContext context{std::cout, std::cerr, [] { return distband::interruptRequested(); }};
  return distband::runDistband(args, context);
}
