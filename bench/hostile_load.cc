// hostile_load: the server under a hostile mix of clients, on loopback, bounded in time (not a timed test).
//   * --maximal-clients (64) concurrent "maximal" queries: each asks for as much as the server would admit alone (a
//     full-domain field whose estimate is about 40 % of the request budget), retrying after RESOURCE_EXHAUSTED; some
//     are cancelled by their client at a random moment;
//   * --stalled-clients (20) stalled uploads (a first chunk, then silence) and --silent-clients (8) clients that never
//     read their query's stream, each replaced as soon as the server gives up on it;
//   * a SIGTERM at 80 % of the run (the server drains for --grace-seconds, then exits).
// It samples the server's RSS and threads from /proc, counts statuses, and reads the server's log for how long each
// cancelled query's engine ran after the cancel was seen.
// Reference: each query kind resolved and computed by the server's own path in this process (bench/server_reference.h).
// Pass: every completed maximal query's field is bit-identical to its reference (else exit 1, naming the kind, the
// grid and the first differing voxel), at least one completed; goals (exit 3): peak RSS <= 1.10 x the budget, exit
// code 0 after the SIGTERM. --smoke: 5 s, a 192 MiB budget, queries of at most 80^3, 6 + 2 + 2 clients.
//
//   build/bench/hostile_load [--seconds 40] [--memory-budget-mib 1536] [--threads 2] [--max-queries 4] [--tag NAME]
//                            [--smoke]
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/chrono.h>
#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <tbb/task_arena.h>

#include "bench/bench_util.h"
#include "client/remote_client.h"
#include "bench/planned_field.h"
#include "bench/server_reference.h"
#include "server/memory_budget.h"
#include "server/request_validation.h"
#include "tests/support/child_server.h"
#include "tests/support/query_requests.h"

namespace distband {
namespace {

using bench::Clock;
using bench::DeliveredField;
using bench::since;

v1::QueryRequest pointQuery(int n, std::vector<Vec3d> points, double limit) {
  return pointsRequest(points, {n, n, n}, 1.0, n / 4.0, limit);
}

struct Tally {
  std::mutex mu;
  std::map<std::string, std::map<std::string, int>> by_kind;  // kind -> status -> count
  int compared = 0, identical = 0;
  std::string first_mismatch;  // what the first wrong field was (bench/planned_field.h's description)
  void add(const std::string& kind, grpc::StatusCode code) {
    static const char* names[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
                                  "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
                                  "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS",
                                  "UNAUTHENTICATED"};
    std::lock_guard lock(mu);
    ++by_kind[kind][int(code) >= 0 && int(code) <= 16 ? names[int(code)] : "OTHER"];
  }
};

int run(int argc, char** argv) {
  double seconds = 40;
  int budget_mib = 1536, threads = 2, max_queries = 4;
  int maximal_clients = 64, stalled_clients = 20, silent_clients = 8, max_size = 1024;
  bool smoke = false;
  std::string tag = "hostile_load", server_log;
  CLI::App app{"hostile_load: the server under stalled, non-reading, cancelling and oversized clients"};
  app.add_option("--seconds", seconds, "length of the run (SIGTERM at 80 %)")->capture_default_str();
  app.add_option("--memory-budget-mib", budget_mib, "the server's --memory-budget")->capture_default_str();
  app.add_option("--threads", threads, "the server's --threads")->capture_default_str();
  app.add_option("--max-queries", max_queries, "the server's --max-queries")->capture_default_str();
  app.add_option("--tag", tag, "output name under bench/results/");
  app.add_option("--server-log", server_log, "write the server's log to this file");
  app.add_option("--maximal-clients", maximal_clients, "clients sending maximal queries")->capture_default_str();
  app.add_option("--stalled-clients", stalled_clients, "clients stalling uploads")->capture_default_str();
  app.add_option("--silent-clients", silent_clients, "clients that never read their stream")->capture_default_str();
  app.add_flag("--smoke", smoke,
               "a few seconds at a small budget with few clients (the CTest run); writes no results file");
  CLI11_PARSE(app, argc, argv);
  if (smoke) {
    seconds = 5;
    budget_mib = 192;
    maximal_clients = 6;
    stalled_clients = 2;
    silent_clients = 2;
    max_size = 80;
  }
  bench::Verdict verdict("hostile_load");

  const double idle_timeout = 3, grace = 3;
  ChildServer server(DISTBAND_SERVER_BIN,
                     {"--threads", std::to_string(threads), "--max-queries", std::to_string(max_queries),
                      "--memory-budget", fmt::format("{}M", budget_mib), "--idle-timeout", fmt::format("{}", idle_timeout),
                      "--grace-seconds", fmt::format("{}", grace), "--queue-wait-ms", "1000", "--max-streams", "128"});
  if (server.port() == 0) {
    std::fprintf(stderr, "the server did not start:\n%s\n", server.log().c_str());
    return 1;
  }
  RemoteClient info_client(server.target());
  v1::ServerInfo info;
  if (!info_client.info(&info).ok()) return 1;
  // A "maximal" query: the largest cube whose estimate fits about 40 % of the request budget (so at most two run at
  // once), found by asking the server's own estimate.
  bench::ServerReference reference;
  int n = 64;
  for (int m = 64; m <= max_size; m += 16) {
    ResolvedQuery q;
    if (!reference.resolve(pointQuery(m, {{m * 0.3, m * 0.4, m * 0.5}}, 0), &q).ok()) break;
    if (double(q.memory.total() + reference.options().stream_buffer_bytes) > 0.4 * double(info.memory_budget_bytes()))
      break;
    n = m;
  }
  const std::vector<v1::QueryRequest> kinds = {
      pointQuery(n, {{n * 0.3, n * 0.4, n * 0.5}}, 0),
      pointQuery(n, {{n * 0.5, n * 0.2, n * 0.7}, {n * 0.9, n * 0.8, n * 0.1}}, 0),
      pointQuery(n, {{n * 0.1, n * 0.9, n * 0.5}}, n / 5.0),
  };
  std::printf("maximal query: %d^3 voxels (request budget %s); computing %zu references...\n", n,
              humanBytes(info.memory_budget_bytes()).c_str(), kinds.size());
  // References: each kind resolved and computed by the server's own path in this process.
  std::vector<DeliveredField> references(kinds.size());
  for (size_t k = 0; k < kinds.size(); ++k)
    if (Status s = reference.field(kinds[k], threads, &references[k]); !s.ok()) {
      verdict.fail(fmt::format("kind {}", k), "the reference cannot be computed: " + s.toString());
      return verdict.finish();
    }

  std::atomic<bool> stop{false};      // the run is over: every client returns
  std::atomic<bool> draining{false};  // SIGTERM was sent: clients finish their current call and start no new one
  std::atomic<int64_t> peak_rss_kb{0}, peak_threads{0};
  std::thread sampler([&] {
    while (!stop) {
      peak_rss_kb = std::max<int64_t>(peak_rss_kb, server.status("VmRSS:"));
      peak_threads = std::max<int64_t>(peak_threads, server.threads());
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  Tally tally;
  std::vector<std::thread> clients;
  // Maximal queries, some cancelled at random.
  for (int c = 0; c < maximal_clients; ++c)
    clients.emplace_back([&, c] {
      std::mt19937 rng(uint32_t(c) * 7919u + 1);
      RemoteClient client(server.target());
      while (!draining) {
        const size_t k = rng() % kinds.size();
        const bool cancel = rng() % 4 == 0;
        const double cancel_after = std::uniform_real_distribution<double>(0.05, 2.0)(rng);
        DeliveredField* field = nullptr;
        std::unique_ptr<DeliveredField> owned;
        const auto start = Clock::now();
        RemoteQueryCallbacks cb;
        cb.on_header = [&](const Grid& g, const v1::QueryHeader&) {
          owned = std::make_unique<DeliveredField>(g);
          field = owned.get();
          return true;
        };
        cb.on_bricks = [&](SegmentBricks&& b, uint64_t) {
          field->add(b);
          return !(cancel && since(start) > cancel_after) && !stop;
        };
        RemoteQueryResult r = client.query(kinds[k], cb);
        tally.add(cancel ? "maximal query (client cancels)" : "maximal query", r.status.error_code());
        if (r.status.ok() && field) {
          const bench::FieldDiff d = bench::compareFields(references[k], *field, bench::FieldTolerance::exact());
          std::lock_guard lock(tally.mu);
          ++tally.compared;
          tally.identical += d.ok;
          if (!d.ok && tally.first_mismatch.empty())
            tally.first_mismatch = fmt::format("kind {} [{}]: {}", k, bench::gridText(references[k].grid()),
                                               d.describe());
        }
        if (!r.status.ok()) std::this_thread::sleep_for(std::chrono::milliseconds(50 + rng() % 200));
      }
    });
  // Stalled uploads.
  for (int c = 0; c < stalled_clients; ++c)
    clients.emplace_back([&] {
      auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials()));
      while (!draining) {
        grpc::ClientContext ctx;
        v1::UploadReply reply;
        auto writer = stub->UploadMesh(&ctx, &reply);
        v1::UploadMeshChunk chunk;
        chunk.mutable_header()->set_format(v1::MESH_FORMAT_OBJ);
        chunk.mutable_header()->set_total_bytes(200 << 20);
        chunk.set_data(std::string(1 << 20, '#'));
        writer->Write(chunk);
        const grpc::StatusCode code = writer->Finish().error_code();  // when the server gives up
        tally.add("stalled upload", code);
        if (code == grpc::StatusCode::RESOURCE_EXHAUSTED) std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    });
  // Clients that never read.
  for (int c = 0; c < silent_clients; ++c)
    clients.emplace_back([&] {
      auto stub = v1::DistanceField::NewStub(grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials()));
      while (!draining) {
        grpc::ClientContext ctx;
        auto reader = stub->Query(&ctx, kinds[0]);
        v1::QueryReply header;
        reader->Read(&header);  // then never read again: the server's writes block
        const auto start = Clock::now();
        while (!stop && since(start) < idle_timeout + 2) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        ctx.TryCancel();
        while (reader->Read(&header)) {
        }
        tally.add("never-reading query", reader->Finish().error_code());
      }
    });

  std::this_thread::sleep_for(std::chrono::duration<double>(seconds * 0.8));
  const auto term_at = Clock::now();
  draining = true;
  server.signal(SIGTERM);
  const int exit_code = server.waitExit(std::chrono::seconds(int(grace) + 30));
  const double exit_seconds = since(term_at);
  stop = true;
  for (auto& t : clients) t.join();
  sampler.join();

  // How long engines ran after the server saw a cancel (its log: engine_stop_after_cancel=...ms).
  std::vector<double> stop_ms;
  const std::string log = server.log();
  if (!server_log.empty()) std::ofstream(server_log) << log;
  const std::regex re(R"(engine_stop_after_cancel=([0-9.]+)ms)");
  for (auto it = std::sregex_iterator(log.begin(), log.end(), re); it != std::sregex_iterator(); ++it)
    stop_ms.push_back(std::stod((*it)[1]));
  const double budget = double(budget_mib) * 1048576.0;
  std::string md = fmt::format(
      "# hostile_load ({:%Y-%m-%d}, {} s, server --threads {} --max-queries {} --memory-budget {}M "
      "--idle-timeout {:g} --grace-seconds {:g})\n\n",
      std::chrono::system_clock::now(), seconds, threads, max_queries, budget_mib, idle_timeout, grace);
  md += fmt::format("maximal query: {}^3 voxels, full domain (3 kinds: 1 point, 2 points, 1 point with a limit)\n\n", n);
  md += "| figure | value |\n|---|---|\n";
  md += fmt::format("| peak RSS | {:.0f} MiB = {:.2f} x budget (goal <= 1.10) |\n", peak_rss_kb / 1024.0,
                    peak_rss_kb * 1024.0 / budget);
  md += fmt::format("| peak threads | {} |\n", peak_threads.load());
  md += fmt::format("| completed queries bit-identical to in-process | {} / {} |\n", tally.identical, tally.compared);
  if (!stop_ms.empty())
    md += fmt::format("| engine run after a cancel was seen (ms), {} cancels | median {:.1f}, max {:.1f} |\n",
                      stop_ms.size(), bench::median(stop_ms), *std::max_element(stop_ms.begin(), stop_ms.end()));
  md += fmt::format("| SIGTERM at {:.0f} s: exit code, seconds to exit | {}, {:.2f} |\n", seconds * 0.8, exit_code,
                    exit_seconds);
  md += "\n| client kind | status counts |\n|---|---|\n";
  for (const auto& [kind, counts] : tally.by_kind) {
    std::string c;
    for (const auto& [name, count] : counts) c += fmt::format("{}{} {}", c.empty() ? "" : ", ", name, count);
    md += fmt::format("| {} | {} |\n", kind, c);
  }
  std::printf("%s", md.c_str());
  if (!smoke) distband::bench::writeResultFile(std::string(DISTBAND_BENCH_DIR) + "/results/" + tag + ".md", md);
  if (tally.compared == 0) verdict.fail("maximal queries", "none completed, so none was checked");
  if (tally.identical != tally.compared)
    verdict.fail("maximal queries", fmt::format("{} of {} completed queries differ from the reference; first: {}",
                                                tally.compared - tally.identical, tally.compared, tally.first_mismatch));
  const int verdict_status = verdict.finish();
  if (verdict_status != 0) return verdict_status;
  // The service's goals: memory within the budget, a clean exit after SIGTERM.
  const bool goals = peak_rss_kb * 1024.0 <= 1.1 * budget && exit_code == 0;
  if (!goals) std::fprintf(stderr, "hostile_load: a goal was missed (peak RSS <= 1.10 x budget, exit code 0)\n");
  return goals ? 0 : 3;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) { return distband::run(argc, argv); }
