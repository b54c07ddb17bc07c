// distband: the command-line entry point. All logic lives in distband_cli_lib (client/cli.h) so tests can run it.
#include <iostream>
#include <string>
#include <vector>

#include "client/cli.h"

int main(int argc, char** argv) {
  distband::installInterruptHandler();
  const std::vector<std::string> args(argv + 1, argv + argc);
  const distband::CliContext context{std::cout, std::cerr, [] { return distband::interruptRequested(); }};
  return distband::runDistband(args, context);
}
