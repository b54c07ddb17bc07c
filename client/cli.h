// The `distband` command line: builds the CLI11 app, registers every subcommand, parses, dispatches.
// Contract: runDistband() never throws and never calls exit(); it returns the process exit code (see
// client/command.h). `args` excludes the program name. Help (-h/--help) prints to `out` and returns 0; any
// parse error (unknown flag, missing value, bad number) prints CLI11's message and a hint to `err` and returns 2.
// To add a subcommand: write register<Name>Command(CLI::App&, const CliContext&) and add one line to
// registerAllCommands() in cli.cc.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "client/command.h"

namespace distband {

int runDistband(const std::vector<std::string>& args, const CliContext& context);

/// Registers every subcommand this build has on `app` (what runDistband parses with; tests read their options).
std::vector<CliCommand> registerAllCommands(CLI::App& app, const CliContext& context);

/// Installs a SIGINT/SIGTERM handler that makes interruptRequested() return true (the first signal asks the
/// engine to stop between steps; the default action is restored, so a second one kills the process).
void installInterruptHandler();
bool interruptRequested();

}  // namespace distband
