#include "client/cli.h"

#include <algorithm>
#include <atomic>
#include <csignal>
#include <exception>

#include "client/at_command.h"
#include "client/compute_command.h"
#ifdef DISTBAND_WITH_SERVICE
#include "client/remote_commands.h"
#endif

namespace distband {
namespace {

std::atomic<bool> g_interrupted{false};

extern "C" void onInterruptSignal(int sig) {
  g_interrupted.store(true);
  std::signal(sig, SIG_DFL);
}

}  // namespace

std::vector<CliCommand> registerAllCommands(CLI::App& app, const CliContext& context) {
  std::vector<CliCommand> commands;
  commands.push_back(registerComputeCommand(app, context));
#ifdef DISTBAND_WITH_SERVICE
  commands.push_back(registerAtCommand(app, context, remoteAt()));
  for (CliCommand& c : registerRemoteCommands(app, context)) commands.push_back(std::move(c));
#else
  // `at` runs in-process here; with --server the front binary hands it to distband-remote before parsing, so --server
  // is registered only for the help (a build without the service refuses it).
  AtRemote local;
  local.add_flags = [](CLI::App* cmd) {
    cmd->add_option_function<std::string>(
        "--server", [](const std::string&) {}, "Run on a distband server HOST:PORT (the service client's flags apply)");
  };
  local.run = [](const AtArgs&, const CliContext& ctx) {
    ctx.err << "distband at: --server needs the service client (built with DISTBAND_BUILD_SERVICE=OFF, or "
            << "distband-remote is missing beside distband)\n";
    return kExitUsage;
  };
  commands.push_back(registerAtCommand(app, context, std::move(local)));
  // Without the service compiled in (the front `distband` binary, or a build without gRPC), the remote commands are
  // listed for --help; the front binary never gets here with them (it hands them to distband-remote first).
  for (const RemoteCommandName& r : kRemoteCommands) {
    CLI::App* cmd = app.add_subcommand(r.name, r.description);
    cmd->allow_extras();
    cmd->prefix_command();
    cmd->set_help_flag();
    commands.push_back({cmd, [&context, name = std::string(r.name)] {
                          context.err << "distband " << name << ": this distband has no service client (built with "
                                      << "DISTBAND_BUILD_SERVICE=OFF, or distband-remote is missing beside it)\n";
                          return kExitUsage;
                        }});
  }
#endif
  return commands;
}

void installInterruptHandler() {
  std::signal(SIGINT, onInterruptSignal);
  std::signal(SIGTERM, onInterruptSignal);
}

bool interruptRequested() { return g_interrupted.load(); }

int runDistband(const std::vector<std::string>& args, const CliContext& context) {
  CLI::App app{"distband: sparse, streamed Euclidean distance fields (active-band distance transform)", "distband"};
  app.require_subcommand(1);
  app.fallthrough(false);
  std::vector<CliCommand> commands;
  try {
    commands = registerAllCommands(app, context);
    if (!args.empty() && !args[0].empty() && args[0][0] != '-') {
      std::string names;
      bool known = false;
      for (const CliCommand& c : commands) {
        known = known || c.app->get_name() == args[0];
        names += (names.empty() ? "" : ", ") + c.app->get_name();
      }
      if (!known) {
        context.err << "distband: unknown command '" << args[0] << "' (commands: " << names << ")\n"
                    << "Run 'distband --help' for usage.\n";
        return kExitUsage;
      }
    }
    std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 consumes a reversed vector
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e, context.out, context.err);
    if (code == 0) return kExitOk;  // --help
    context.err << "Run 'distband --help' or 'distband <command> --help' for usage.\n";
    return kExitUsage;
  } catch (const std::exception& e) {
    context.err << "distband: " << e.what() << "\n";
    return kExitUsage;
  }
  for (const CliCommand& c : commands) {
    if (!c.app->parsed()) continue;
    try {
      return c.run();
    } catch (const std::exception& e) {
      context.err << "distband " << c.app->get_name() << ": internal error: " << e.what() << "\n";
      return kExitFailure;
    }
  }
  context.err << "distband: no command given\n";
  return kExitUsage;
}

}  // namespace distband
