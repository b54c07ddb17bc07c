// metrics_overhead: what --metrics-listen costs, and what a scrape weighs. In one run it starts two distband-server
// processes on loopback, identical but for --metrics-listen, and:
//   1. runs the same queries on both, alternating (A B B A per round, so drift cancels): full-domain N^3 queries (one
//      point, then the bunny mesh, as service_bench does) and a block of small 32^3 queries (the per-call part);
//      medians per server and the difference (goal <= 2 %);
//   2. makes --calls GetInfo calls (default 10^6) on the server with metrics, from --clients threads, then scrapes
//      /metrics: its size in bytes (goal < 64 KiB) and whether the call counter says --calls.
// Output: a markdown table on stdout and a JSON file (--json).
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "client/remote_client.h"
#include "tests/support/child_server.h"
#include "tests/support/http_get.h"

namespace distband {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

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

double sample(const std::string& text, const std::string& series) {
  const size_t at = text.find("\n" + series + " ");
  return at == std::string::npos ? -1 : std::stod(text.substr(at + series.size() + 2));
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"metrics_overhead: distband-server with --metrics-listen against without, in one run"};
  int resolution = 192, threads = 2, rounds = 5, small = 200, clients = 4;
  uint64_t calls = 1000000;
  std::string mesh_path = DISTBAND_BENCH_DIR "/../tests/data/meshes/bunny.obj", json_path;
  app.add_option("--resolution", resolution, "N of the full-domain N^3 queries")->capture_default_str();
  app.add_option("--threads", threads, "--threads of both servers")->capture_default_str();
  app.add_option("--rounds", rounds, "rounds of A B B A")->capture_default_str();
  app.add_option("--small", small, "32^3 queries per block (the per-call part)")->capture_default_str();
  app.add_option("--calls", calls, "GetInfo calls before the scrape whose size is measured")->capture_default_str();
  app.add_option("--clients", clients, "threads (each with its own channel) making the GetInfo calls")
      ->capture_default_str();
  app.add_option("--mesh", mesh_path, "the mesh of the second full-domain case")->capture_default_str();
  app.add_option("--json", json_path, "write the results here too");
  CLI11_PARSE(app, argc, argv);

  const std::vector<std::string> common = {"--threads", std::to_string(threads), "--max-queries", "1",
                                           "--memory-budget", "4G"};
  std::vector<std::string> with = common;
  with.insert(with.end(), {"--metrics-listen", "127.0.0.1:0"});
  ServerProcess off(common), on(with);
  RemoteClient client_off(off.target()), client_on(on.target());
  std::printf("servers: metrics off on %s, metrics on on %s (metrics port %d); %d threads each\n",
              off.target().c_str(), on.target().c_str(), on.metricsPort(), threads);

  v1::UploadReply up_off, up_on;
  if (!client_off.uploadMeshFile(mesh_path, &up_off).ok() || !client_on.uploadMeshFile(mesh_path, &up_on).ok()) {
    std::fprintf(stderr, "cannot upload %s\n", mesh_path.c_str());
    return 1;
  }
  struct Case {
    std::string name;
    std::vector<v1::QueryRequest> requests;  // run back to back, timed together
    std::vector<double> off, on;
  };
  std::vector<Case> cases;
  cases.push_back({fmt::format("1 point, {}^3, full domain", resolution), {pointQuery(resolution)}, {}, {}});
  v1::QueryRequest bunny;
  bunny.set_asset_id(up_on.asset_id());  // content-addressed: the same id on both
  bunny.mutable_grid()->set_resolution(uint32_t(resolution));
  bunny.set_segment_length(0.1);
  cases.push_back({fmt::format("bunny, {}^3, full domain", resolution), {bunny}, {}, {}});
  Case many{fmt::format("{} queries, 1 point, 32^3", small), {}, {}, {}};
  for (int i = 0; i < small; ++i) many.requests.push_back(pointQuery(32));
  cases.push_back(many);

  auto run = [](RemoteClient& client, const Case& c) {
    double s = 0;
    for (const v1::QueryRequest& r : c.requests) s += timeQuery(client, r);
    return s;
  };
  for (Case& c : cases) {  // warm-up, untimed
    run(client_off, c);
    run(client_on, c);
  }
  for (int round = 0; round < rounds; ++round)
    for (Case& c : cases) {
      c.off.push_back(run(client_off, c));
      c.on.push_back(run(client_on, c));
      c.on.push_back(run(client_on, c));
      c.off.push_back(run(client_off, c));
    }

  nlohmann::json out;
  out["resolution"] = resolution;
  out["threads"] = threads;
  out["rounds"] = rounds;
  std::printf("\n| case | metrics off (median s) | metrics on (median s) | on / off - 1 |\n|---|---|---|---|\n");
  for (const Case& c : cases) {
    const double a = median(c.off), b = median(c.on);
    std::printf("| %s | %.4f | %.4f | %+.2f %% |\n", c.name.c_str(), a, b, 100 * (b / a - 1));
    out["cases"].push_back({{"name", c.name}, {"off_s", c.off}, {"on_s", c.on}, {"off_median_s", a},
                            {"on_median_s", b}, {"difference_percent", 100 * (b / a - 1)}});
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
  if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  return scrape.status == 200 && failed.load() == 0 ? 0 : 1;
}
