// Server flags: binds every ServerOptions field to a CLI11 option of distband-server.
// Contract: addServerFlags only registers options (defaults shown from `options`); the caller parses and then
// calls options->validate().
#pragma once

#include <CLI/CLI.hpp>

#include "server/server_options.h"

namespace distband {

void addServerFlags(CLI::App& app, ServerOptions* options);

}  // namespace distband
