// metrics_overhead: what --metrics-listen costs, and what a scrape weighs. In one run it starts three distband-server
// processes on loopback — without metrics, with --metrics-listen, and without again (the noise floor) — and:
//   1. runs the same queries on all three, in a rotating order each round: full-domain N^3 queries (one point, then
//      the bunny mesh, as service_bench does) and a block of small 32^3 queries (the per-call part); the median of
//      the per-round ratios against the first server (goal <= 2 %), beside the same for the identical third server;
//   2. makes --calls GetInfo calls (default 10^6) on the server with metrics, from --clients threads, then scrapes
//      /metrics: its size in bytes (goal < 64 KiB) and whether the call counter says --calls.
// Output: a markdown table on stdout and a JSON file (--json).
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "bench/bench_util.h"
#include "client/remote_client.h"
#include "server/metrics.h"
#include "tests/support/child_server.h"
#include "tests/support/http_get.h"

namespace distband {
namespace {

using bench::Clock;
using bench::median;
using bench::since;

class ServerProcess : public ChildServer {
 public:
  ServerProcess(const std::vector<std::string>& args) : ChildServer(DISTBAND_SERVER_BIN, args) {
    if (port() == 0) throw std::runtime_error("distband-server did not start: " + log());
    std::smatch m;
    const std::string text = log();
    if (std::regex_search(text, m, std::regex(R"(metrics: http://\S+ \(port (\d+);)"))) metrics_port_ = std::stoi(m[1]);
  }
  ~ServerProcess() {
    signal(SIGTERM);
    waitExit(std::chrono::seconds(30));
  }
  int metricsPort() const { return metrics_port_; }
  /// CPU seconds (user + system) the server has used so far, exited threads included (/proc/PID/stat).
  double cpuSeconds() const {
    std::ifstream in("/proc/" + std::to_string(pid()) + "/stat");
    const std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::istringstream fields(stat.substr(stat.rfind(')') + 2));
    std::vector<std::string> f;
    for (std::string x; fields >> x;) f.push_back(x);
    return f.size() > 12 ? (std::stod(f[11]) + std::stod(f[12])) / double(sysconf(_SC_CLK_TCK)) : 0;
  }

 private:
  int metrics_port_ = 0;
};

v1::QueryRequest pointQuery(int n) {
  v1::QueryRequest r;
  v1::Vec3* p = r.mutable_points()->add_points();
  p->set_x(n * 0.3 + 0.25);
  p->set_y(n * 0.4 + 0.5);
  p->set_z(n * 0.35 + 0.1);
  r.mutable_grid()->set_voxel_size(1.0);
  r.mutable_grid()->mutable_dims()->set_x(uint32_t(n));
  r.mutable_grid()->mutable_dims()->set_y(uint32_t(n));
  r.mutable_grid()->mutable_dims()->set_z(uint32_t(n));
  r.set_segment_length(n / 8.0);
  return r;
}

/// Seconds for one whole query (every message read); throws on an error.
double timeQuery(RemoteClient& client, const v1::QueryRequest& request) {
  RemoteQueryCallbacks cb;
  cb.on_bricks = [](SegmentBricks&&, uint64_t) { return true; };
  const auto t0 = Clock::now();
  const RemoteQueryResult r = client.query(request, cb);
  const double s = since(t0);
  if (!r.status.ok()) throw std::runtime_error("query failed: " + r.status.error_message());
  return s;
}

/// What one query's handler reports (server/distance_field_service.cc), `messages` replies written: nanoseconds a
/// query, over `n` queries on one thread.
double reportNanoseconds(Metrics& m, int n, int messages) {
  const auto t0 = Clock::now();
  for (int i = 0; i < n; ++i) {
    m.queryQueued(1);
    m.queryQueued(-1);
    m.queryAdmitted(1e-4);
    m.queryRunning(1);
    for (int k = 0; k < messages; ++k) {
      m.querySentBytes(1 << 20);
      if (k == 1) m.queryFirstBrick(0.01);
    }
    m.querySentVoxels(32768);
    m.queryComputed(1e-3, 2e-3);
    m.queryRunning(-1);
    m.callEnded(Rpc::kQuery, grpc::StatusCode::OK, 0.005);
  }
  return since(t0) * 1e9 / n;
}

double sample(const std::string& text, const std::string& series) {
  const size_t at = text.find("\n" + series + " ");
  return at == std::string::npos ? -1 : std::stod(text.substr(at + series.size() + 2));
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"metrics_overhead: distband-server with --metrics-listen against without, in one run"};
  int resolution = 192, threads = 2, rounds = 7, small = 200, clients = 4;
  uint64_t calls = 1000000;
  std::string mesh_path = DISTBAND_BENCH_DIR "/../tests/data/meshes/bunny.obj", json_path;
  app.add_option("--resolution", resolution, "N of the full-domain N^3 queries")->capture_default_str();
  app.add_option("--threads", threads, "--threads of every server")->capture_default_str();
  app.add_option("--rounds", rounds, "rounds; each runs every case on the three servers, in a rotating order")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--small", small, "32^3 queries per block (the per-call part)")->capture_default_str();
  app.add_option("--calls", calls, "GetInfo calls before the scrape whose size is measured")->capture_default_str();
  app.add_option("--clients", clients, "threads (each with its own channel) making the GetInfo calls")
      ->capture_default_str();
  app.add_option("--mesh", mesh_path, "the mesh of the second full-domain case")->capture_default_str();
  app.add_option("--json", json_path, "write the results here too");
  CLI11_PARSE(app, argc, argv);
  nlohmann::json out_early;

  // In process first: what a query's reports cost, with metrics on and off (the hot path's share of a query).
  {
    auto enabled = Metrics::enabled(), disabled = Metrics::disabled();
    const int n = 1000000, messages = 20;
    reportNanoseconds(*enabled, n / 10, messages);  // warm-up
    const double on_ns = reportNanoseconds(*enabled, n, messages), off_ns = reportNanoseconds(*disabled, n, messages);
    const auto t0 = Clock::now();
    const std::string text = enabled->text();
    const double scrape_us = since(t0) * 1e6;
    std::printf("in process: one query's reports (%d replies) cost %.0f ns with metrics on, %.1f ns off; rendering a "
                "scrape (%zu bytes) %.0f us\n",
                messages, on_ns, off_ns, text.size(), scrape_us);
    nlohmann::json& r = out_early["reports"];
    r["messages"] = messages;
    r["on_ns_per_query"] = on_ns;
    r["off_ns_per_query"] = off_ns;
    r["scrape_render_us"] = scrape_us;
  }

  // Three servers: metrics off (A), metrics on (B) and a second one without (A'), whose difference from A is the
  // noise floor of this machine: a figure for B is only as good as A' against A.
  const std::vector<std::string> common = {"--threads", std::to_string(threads), "--max-queries", "1",
                                           "--memory-budget", "4G"};
  std::vector<std::string> with = common;
  with.insert(with.end(), {"--metrics-listen", "127.0.0.1:0"});
  ServerProcess off(common), on(with), control(common);
  const ServerProcess* servers[3] = {&off, &on, &control};
  RemoteClient client_off(off.target()), client_on(on.target()), client_control(control.target());
  RemoteClient* clients_by_server[3] = {&client_off, &client_on, &client_control};
  std::printf("servers: metrics off %s, metrics on %s (metrics port %d), metrics off again %s; %d threads each\n",
              off.target().c_str(), on.target().c_str(), on.metricsPort(), control.target().c_str(), threads);

  v1::UploadReply up;
  for (RemoteClient* c : clients_by_server)
    if (!c->uploadMeshFile(mesh_path, &up).ok()) {
      std::fprintf(stderr, "cannot upload %s\n", mesh_path.c_str());
      return 1;
    }
  struct Case {
    std::string name;
    std::vector<v1::QueryRequest> requests;  // run back to back, timed together
    std::vector<double> seconds[3];          // per server: off, on, control
    std::vector<double> on_ratio, control_ratio;  // per round, against off
    double cpu[3] = {0, 0, 0};               // the servers' CPU seconds over every round
  };
  std::vector<Case> cases;
  cases.push_back({fmt::format("1 point, {}^3, full domain", resolution), {pointQuery(resolution)}, {}, {}, {}});
  v1::QueryRequest bunny;
  bunny.set_asset_id(up.asset_id());  // content-addressed: the same id on every server
  bunny.mutable_grid()->set_resolution(uint32_t(resolution));
  bunny.set_segment_length(0.1);
  cases.push_back({fmt::format("bunny, {}^3, full domain", resolution), {bunny}, {}, {}, {}});
  Case many{fmt::format("{} queries, 1 point, 32^3", small), {}, {}, {}, {}};
  for (int i = 0; i < small; ++i) many.requests.push_back(pointQuery(32));
  cases.push_back(many);

  auto run = [](RemoteClient& client, const Case& c) {
    double s = 0;
    for (const v1::QueryRequest& r : c.requests) s += timeQuery(client, r);
    return s;
  };
  for (Case& c : cases)  // warm-up, untimed
    for (RemoteClient* client : clients_by_server) run(*client, c);
  // Each round runs every case on the three servers in one of the six orders (rotating), so no server is always
  // first or last; the ratios are taken within a round (drift between rounds cancels).
  const int orders[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  for (int round = 0; round < rounds; ++round)
    for (Case& c : cases) {
      double t[3];
      for (int k : orders[round % 6]) {
        const double cpu0 = servers[k]->cpuSeconds();
        t[k] = run(*clients_by_server[k], c);
        c.cpu[k] += servers[k]->cpuSeconds() - cpu0;
      }
      for (int k = 0; k < 3; ++k) c.seconds[k].push_back(t[k]);
      c.on_ratio.push_back(t[1] / t[0]);
      c.control_ratio.push_back(t[2] / t[0]);
    }

  nlohmann::json out = out_early;
  out["resolution"] = resolution;
  out["threads"] = threads;
  out["rounds"] = rounds;
  std::printf("\n%d rounds. Time: the median of the per-round ratios against the server without metrics; CPU: the "
              "servers' CPU seconds over all rounds (/proc), against the same. The second server without metrics "
              "is the noise floor.\n\n"
              "| case | metrics off: median s, CPU s | metrics on / off: time, CPU | second server without / off: "
              "time, CPU |\n|---|---|---|---|\n",
              rounds);
  for (const Case& c : cases) {
    const double a = median(c.seconds[0]), on_pct = 100 * (median(c.on_ratio) - 1),
                 control_pct = 100 * (median(c.control_ratio) - 1), on_cpu = 100 * (c.cpu[1] / c.cpu[0] - 1),
                 control_cpu = 100 * (c.cpu[2] / c.cpu[0] - 1);
    std::printf("| %s | %.4f, %.2f | %+.2f %%, %+.2f %% | %+.2f %%, %+.2f %% |\n", c.name.c_str(), a, c.cpu[0], on_pct,
                on_cpu, control_pct, control_cpu);
    out["cases"].push_back({{"name", c.name},
                            {"off_s", c.seconds[0]},
                            {"on_s", c.seconds[1]},
                            {"control_s", c.seconds[2]},
                            {"cpu_s", {c.cpu[0], c.cpu[1], c.cpu[2]}},
                            {"on_vs_off_percent", on_pct},
                            {"control_vs_off_percent", control_pct},
                            {"on_vs_off_cpu_percent", on_cpu},
                            {"control_vs_off_cpu_percent", control_cpu}});
  }

  // 10^6 cheap calls, then the scrape.
  const auto t0 = Clock::now();
  std::atomic<uint64_t> next{0}, failed{0};
  std::vector<std::thread> workers;
  for (int t = 0; t < clients; ++t)
    workers.emplace_back([&, t] {
      grpc::ChannelArguments args;
      args.SetInt("distband.bench.channel", t);  // one connection per thread
      auto stub = v1::DistanceField::NewStub(
          grpc::CreateCustomChannel(on.target(), grpc::InsecureChannelCredentials(), args));
      while (next.fetch_add(1) < calls) {
        grpc::ClientContext context;
        v1::ServerInfo info;
        if (!stub->GetInfo(&context, {}, &info).ok()) failed.fetch_add(1);
      }
    });
  for (std::thread& w : workers) w.join();
  const double call_seconds = since(t0);
  const HttpResponse scrape = httpGet(on.metricsPort(), "/metrics");
  const double counted = sample(scrape.body, R"(distband_calls_total{code="OK",rpc="GetInfo"})");
  std::printf("\n%llu GetInfo calls from %d threads in %.1f s (%.0f calls/s, %llu failed); the scrape after them: "
              "HTTP %d, %zu bytes (goal < 65536), distband_calls_total{rpc=\"GetInfo\",code=\"OK\"} = %.0f\n",
              static_cast<unsigned long long>(calls), clients, call_seconds, calls / call_seconds,
              static_cast<unsigned long long>(failed.load()), scrape.status, scrape.body.size(), counted);
  out["calls"] = calls;
  out["call_seconds"] = call_seconds;
  out["calls_failed"] = failed.load();
  out["scrape_status"] = scrape.status;
  out["scrape_bytes"] = scrape.body.size();
  out["scrape_getinfo_ok"] = counted;
  if (!json_path.empty()) bench::writeResultFile(json_path, out.dump(2) + "\n");
  return scrape.status == 200 && failed.load() == 0 ? 0 : 1;
}
