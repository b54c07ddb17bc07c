// service_bench: what the network path costs. Starts the real distband-server as a child process on loopback and,
// in the same run, the server's own query path in this process (bench/server_reference.h) on the same request:
//   1. full-domain N^3 queries (no limit; points, then the bunny mesh; --volumes adds uploaded seed volumes, with and
//      without --volume-limit-voxels): time until the first segment's bricks reach the client vs the whole query
//      (goal <= 10 %), and the whole stream vs the in-process run (goal <= 1.2x); with --baseline-server-bin each
//      query also runs on that server (another build), alternating, so a change is timed against the code before it
//      in the same run;
//   2. --concurrent queries against a server with --max-queries: every query completes with the reference field or
//      gets RESOURCE_EXHAUSTED; the server's peak RSS is sampled from /proc.
// Reference: the request resolved and computed by the server's code in this process (resolveQuery ->
// buildFieldInputs -> computeField, the mesh parsed from the same bytes by the server's parser). Every streamed field
// is compared with it voxel by voxel after the clock stops, and every in-process run with the first.
// Pass: every field equal, no load-test query wrong or failed with another status, at least one completed; else each
// failure is printed (case, grid, first differing voxel) and the exit status is 1. The timing goals are reported,
// not checked.
// Output: a markdown table on stdout and a JSON file (--json).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "bench/server_reference.h"
#include "client/remote_client.h"
#include "tests/support/child_server.h"
#include "tests/support/query_requests.h"

namespace distband {
namespace {

using bench::Clock;
using bench::DeliveredField;
using bench::FieldDiff;
using bench::FieldTolerance;
using bench::ServerReference;
using bench::since;

// ---- the server child process ----
class ServerProcess : public ChildServer {
 public:
  ServerProcess(const std::string& bin, const std::vector<std::string>& extra) : ChildServer(bin, extra) {
    if (port() == 0) throw std::runtime_error("distband-server did not start: " + log());
  }
  ~ServerProcess() {
    signal(SIGTERM);
    waitExit(std::chrono::seconds(30));
  }
  /// VmRSS / VmHWM of the server in MB.
  double rssMb(const char* field = "VmRSS:") const { return double(status(field)) / 1024.0; }
};

struct Case {
  std::string name;
  v1::QueryRequest request;
};

/// Every brick a query delivered, kept while it streams and recorded after the clock stops.
struct Kept {
  std::vector<SegmentBricks> segments;
  DeliveredField field(const Grid& grid) const {
    DeliveredField f(grid);
    for (const SegmentBricks& s : segments) f.add(s);
    return f;
  }
};

struct InProcess {
  double seconds = 0;  ///< buildFieldInputs + computeField, as the server's query job runs them
  Kept kept;
};

/// The request run in this process by the server's own path (bench/server_reference.h).
InProcess runInProcess(ServerReference& reference, const ResolvedQuery& q, int threads) {
  InProcess r;
  ServerReference::Run run;
  if (Status s = reference.run(q, threads, [&](SegmentBricks&& b) { r.kept.segments.push_back(std::move(b)); }, &run);
      !s.ok())
    throw std::runtime_error("in-process run: " + s.toString());
  r.seconds = run.total_seconds;
  return r;
}

struct Remote {
  RemoteQueryResult result;
  Kept kept;
};

Remote runRemote(RemoteClient& client, const v1::QueryRequest& request) {
  Remote r;
  RemoteQueryCallbacks cb;
  cb.on_bricks = [&](SegmentBricks&& b, uint64_t) {
    r.kept.segments.push_back(std::move(b));
    return true;
  };
  r.result = client.query(request, cb);
  return r;
}

/// The voxel size the server's path gives `request` (to state a segment length in voxels of it).
double voxelSizeOf(ServerReference& reference, const v1::QueryRequest& request) {
  ResolvedQuery q;
  if (Status s = reference.resolve(request, &q); !s.ok()) throw std::runtime_error("resolve: " + s.toString());
  return q.grid.voxelSize();
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"service_bench: loopback query cost vs the in-process engine, and server RSS under load"};
  std::string server_bin = DISTBAND_SERVER_BIN;
  std::string mesh_path = DISTBAND_BENCH_DIR "/../tests/data/meshes/bunny.obj";
  int resolution = 256, threads = 2, repeat = 3;
  double segment_voxels = 4;
  int concurrent = 16, max_queries = 4, load_resolution = 256;
  double load_limit_voxels = 12;
  std::string json_path = DISTBAND_BENCH_DIR "/results/service_bench.json";
  std::string baseline_bin;
  std::vector<std::string> volumes;
  std::vector<double> volume_limits{0, 10};
  bool point_case = true;
  app.add_option("--server-bin", server_bin, "distband-server binary")->capture_default_str();
  app.add_option("--mesh", mesh_path, "mesh for the mesh case ('' to skip)")->capture_default_str();
  app.add_option("--resolution", resolution, "N of the full-domain N^3 queries")->capture_default_str();
  app.add_option("--threads", threads, "compute threads (server and in-process)")->capture_default_str();
  app.add_option("--repeat", repeat, "runs per case (median reported)")->capture_default_str();
  app.add_option("--segment-voxels", segment_voxels, "segment length in voxels")->capture_default_str();
  app.add_option("--concurrent", concurrent, "queries in the load test")->capture_default_str();
  app.add_option("--max-queries", max_queries, "server --max-queries in the load test")->capture_default_str();
  app.add_option("--load-resolution", load_resolution, "N of the load-test queries (bunny)")->capture_default_str();
  app.add_option("--load-limit-voxels", load_limit_voxels, "limit of the load-test queries, voxels")
      ->capture_default_str();
  app.add_option("--json", json_path, "JSON output ('' for none)")->capture_default_str();
  app.add_option("--baseline-server-bin", baseline_bin,
                 "another distband-server build: each query also runs there, alternating (timed against it)");
  app.add_option("--volumes", volumes,
                 "uploaded volume cases KIND:N, KIND shell (a sphere shell, signed: mask-inside) or blobs (40 balls, "
                 "unsigned)");
  app.add_option("--volume-limit-voxels", volume_limits, "limits of the volume cases, voxels (0: none)")
      ->capture_default_str();
  app.add_option("--point-case", point_case, "run the 1-point full-domain case")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  bench::Verdict verdict("service_bench");
  nlohmann::json out;
  out["threads"] = threads;
  out["resolution"] = resolution;
  out["cases"] = nlohmann::json::array();
  std::string md = fmt::format(
      "| case | in-process s | stream s | stream / in-process | first bricks s | first / total | MB streamed | "
      "field equal |{}\n|---|---|---|---|---|---|---|---|{}\n",
      baseline_bin.empty() ? "" : " baseline stream s | baseline first / total | stream / baseline |",
      baseline_bin.empty() ? "" : "---|---|---|");

  // The reference side: the same bytes the server is sent, parsed by the server's own code.
  ServerReference reference;
  std::string mesh_bytes, mesh_id;
  if (!mesh_path.empty()) {
    std::ifstream in(mesh_path, std::ios::binary);
    mesh_bytes.assign(std::istreambuf_iterator<char>(in), {});
    if (Status e = reference.addMesh(mesh_bytes, meshFormatFromPath(mesh_path), "bunny", &mesh_id); !e.ok()) {
      fmt::print(stderr, "skipping the mesh cases: {}\n", e.toString());
      mesh_id.clear();
    }
  }
  const bool have_mesh = !mesh_id.empty();
  // Uploads the mesh to a server; its id must be the reference's (the server content-addresses the same bytes).
  auto upload = [&](RemoteClient& client) {
    v1::UploadReply up;
    if (grpc::Status s = client.uploadMesh(mesh_bytes, meshFormatFromPath(mesh_path), "bunny", &up); !s.ok())
      throw std::runtime_error("upload failed: " + s.error_message());
    if (up.asset_id() != mesh_id)
      verdict.fail("upload", fmt::format("the server's asset id {} differs from the reference's {}", up.asset_id(),
                                         mesh_id));
    return up.asset_id();
  };

  try {
    {
      const std::vector<std::string> server_args{"--threads",          std::to_string(threads),
                                                 "--max-queries",      "4",
                                                 "--max-upload-bytes", std::to_string(uint64_t(1) << 30)};
      ServerProcess server(server_bin, server_args);
      RemoteClient client(server.target());
      std::optional<ServerProcess> baseline;
      std::optional<RemoteClient> baseline_client;
      if (!baseline_bin.empty()) {
        baseline.emplace(baseline_bin, server_args);
        baseline_client.emplace(baseline->target());
      }

      std::vector<Case> cases;
      if (point_case) {  // one point near a corner: the field grows over the whole domain, many segments
        const Vec3d p{resolution * 0.3 + 0.25, resolution * 0.4 + 0.5, resolution * 0.35 + 0.1};
        cases.push_back({fmt::format("1 point, {}^3, full domain", resolution),
                         pointsRequest({p}, {resolution, resolution, resolution}, 1.0, segment_voxels, 0)});
      }
      if (have_mesh) {
        Case c{fmt::format("bunny, {}^3, full domain", resolution), {}};
        c.request.set_asset_id(upload(client));
        c.request.mutable_grid()->set_resolution(uint32_t(resolution));
        c.request.set_segment_length(segment_voxels * voxelSizeOf(reference, c.request));
        cases.push_back(std::move(c));
      }
      for (const std::string& spec : volumes) {
        const size_t colon = spec.find(':');
        const std::string kind = spec.substr(0, colon);
        const int n = colon == std::string::npos ? resolution : std::stoi(spec.substr(colon + 1));
        if (kind != "shell" && kind != "blobs") throw std::runtime_error("--volumes: unknown kind " + kind);
        const std::vector<uint8_t> mask = kind == "shell" ? bench::sphereShellMask(n) : bench::randomBlobsMask(n);
        v1::Dims dims;
        dims.set_x(uint32_t(n));
        dims.set_y(uint32_t(n));
        dims.set_z(uint32_t(n));
        std::string id, bytes(mask.begin(), mask.end());
        if (Status e = reference.addVolume(dims, bytes, kind, &id); !e.ok())
          throw std::runtime_error("reference volume: " + e.toString());
        for (RemoteClient* to : {&client, baseline_client ? &*baseline_client : nullptr}) {
          if (!to) continue;
          v1::UploadReply up;
          if (grpc::Status st = to->uploadVolumeBytes({n, n, n}, v1::VOXEL_TYPE_UINT8, mask, kind, &up); !st.ok())
            throw std::runtime_error("volume upload failed: " + st.error_message());
          if (up.asset_id() != id) verdict.fail("upload", "the server's volume id differs from the reference's");
        }
        for (double limit : volume_limits) {
          Case c{fmt::format("{} volume{}, {}^3, {}", kind, kind == "shell" ? " (signed)" : "", n,
                             limit > 0 ? fmt::format("limit {} voxels", limit) : std::string("full domain")),
                 {}};
          c.request.set_asset_id(id);
          c.request.mutable_grid()->set_voxel_size(1.0);
          if (kind == "shell") c.request.set_sign(v1::SIGN_MODE_MASK_INSIDE);
          if (limit > 0) c.request.set_limit_voxels(limit);
          c.request.set_segment_length(segment_voxels);
          cases.push_back(std::move(c));
        }
      }

      for (const Case& c : cases) {
        ResolvedQuery q;
        if (Status s = reference.resolve(c.request, &q); !s.ok()) {
          verdict.fail(c.name, "the reference cannot resolve the request: " + s.toString());
          continue;
        }
        std::vector<double> inproc, stream, first, base_stream, base_first;
        std::optional<DeliveredField> ref;
        double mb = 0;
        bool equal = true;
        for (int i = 0; i < repeat; ++i) {
          InProcess ip = runInProcess(reference, q, threads);
          inproc.push_back(ip.seconds);
          DeliveredField mine = ip.kept.field(q.grid);
          ip.kept = {};
          if (!ref) {
            ref = std::move(mine);
          } else if (const FieldDiff d = compareFields(*ref, mine, FieldTolerance::exact()); !d.ok) {
            verdict.fail(c.name, q.grid, fmt::format("in-process run {} differs from run 0: {}", i, d.describe()));
          }
          Remote rm = runRemote(client, c.request);
          if (!rm.result.status.ok()) {
            verdict.fail(c.name, q.grid, "query failed: " + rm.result.status.error_message());
            equal = false;
            break;
          }
          stream.push_back(rm.result.total_seconds);
          first.push_back(rm.result.first_bricks_seconds);
          if (baseline_client) {
            Remote base = runRemote(*baseline_client, c.request);
            if (!base.result.status.ok()) {
              verdict.fail(c.name, q.grid, "baseline query failed: " + base.result.status.error_message());
            } else {
              base_stream.push_back(base.result.total_seconds);
              base_first.push_back(base.result.first_bricks_seconds);
              if (const FieldDiff d = compareFields(*ref, base.kept.field(base.result.grid), FieldTolerance::exact());
                  !d.ok)
                verdict.fail(c.name, q.grid, "the baseline's field is not the reference: " + d.describe());
              fmt::print(stderr, "{} run {}: baseline stream {:.3f}s, first bricks {:.3f}s\n", c.name, i,
                         base.result.total_seconds, base.result.first_bricks_seconds);
            }
          }
          mb = rm.result.wire_bytes / 1e6;
          const FieldDiff d = compareFields(*ref, rm.kept.field(rm.result.grid), FieldTolerance::exact());
          if (!d.ok) {
            equal = false;
            verdict.fail(c.name, q.grid, fmt::format("run {}: the streamed field is not the reference: {}", i,
                                                     d.describe()));
          }
          fmt::print(stderr, "{} run {}: in-process {:.3f}s, stream {:.3f}s (server compute {:.3f}s), first bricks "
                     "{:.3f}s, {} segments, {}\n", c.name, i, ip.seconds, rm.result.total_seconds,
                     rm.result.summary.compute_seconds(), rm.result.first_bricks_seconds,
                     rm.result.summary.segments_size(), d.ok ? "equal" : "NOT EQUAL");
        }
        if (stream.empty()) continue;
        const double ip = bench::median(inproc), st = bench::median(stream), fb = bench::median(first);
        md += fmt::format("| {} | {:.3f} | {:.3f} | {:.2f}x | {:.3f} | {:.1f} % | {:.1f} | {} |", c.name, ip, st,
                          st / ip, fb, 100 * fb / st, mb, equal ? "yes" : "NO");
        nlohmann::json row{{"case", c.name},
                           {"in_process_s", ip},
                           {"stream_s", st},
                           {"ratio", st / ip},
                           {"first_bricks_s", fb},
                           {"first_fraction", fb / st},
                           {"mb", mb},
                           {"segment_voxels", segment_voxels},
                           {"field_equal", equal},
                           {"in_process_runs", inproc},
                           {"stream_runs", stream},
                           {"first_runs", first}};
        if (!base_stream.empty()) {
          const double bs = bench::median(base_stream), bf = bench::median(base_first);
          md += fmt::format(" {:.3f} | {:.1f} % | {:.2f}x |", bs, 100 * bf / bs, st / bs);
          row["baseline_stream_s"] = bs;
          row["baseline_first_fraction"] = bf / bs;
          row["stream_vs_baseline"] = st / bs;
          row["baseline_stream_runs"] = base_stream;
          row["baseline_first_runs"] = base_first;
        }
        md += "\n";
        out["cases"].push_back(std::move(row));
      }
    }

    // ---- load: concurrent queries on a server limited to max_queries ----
    std::string md_load;
    if (concurrent > 0) {
      ServerProcess server(server_bin,
                           {"--threads", std::to_string(threads), "--max-queries", std::to_string(max_queries)});
      RemoteClient client(server.target());
      v1::QueryRequest req;
      const bool use_mesh = have_mesh;
      if (use_mesh) {
        req.set_asset_id(upload(client));
        req.mutable_grid()->set_resolution(uint32_t(load_resolution));
      } else {
        const Vec3d p{load_resolution * 0.5, load_resolution * 0.5, load_resolution * 0.5};
        req = pointsRequest({p}, {load_resolution, load_resolution, load_resolution}, 1.0, 0, 0);
      }
      req.set_limit_voxels(load_limit_voxels);
      req.set_segment_length(4 * voxelSizeOf(reference, req));
      const std::string load_name = fmt::format("load: {} {}^3, limit {} voxels", use_mesh ? "bunny" : "1 point",
                                                load_resolution, load_limit_voxels);
      DeliveredField ref;
      ResolvedQuery q;
      if (Status s = reference.field(req, threads, &ref, &q); !s.ok())
        throw std::runtime_error("the load test's reference: " + s.toString());

      const double idle_rss = server.rssMb();
      std::atomic<bool> sampling{true};
      double peak_rss = idle_rss;
      std::thread sampler([&] {
        while (sampling) {
          peak_rss = std::max(peak_rss, server.rssMb());
          std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
      });
      std::vector<Remote> results(static_cast<size_t>(concurrent));
      std::vector<std::thread> clients;
      const auto t0 = Clock::now();
      for (int i = 0; i < concurrent; ++i)
        clients.emplace_back([&, i] { results[size_t(i)] = runRemote(client, req); });
      for (auto& t : clients) t.join();
      const double wall = since(t0);
      sampling = false;
      sampler.join();
      const double hwm = server.rssMb("VmHWM:");
      // Compared after the clock: every completed query against the reference, voxel by voxel.
      int correct = 0, exhausted = 0, wrong = 0, failed = 0;
      for (int i = 0; i < concurrent; ++i) {
        Remote& r = results[size_t(i)];
        const std::string name = fmt::format("{}, query {}", load_name, i);
        if (r.result.status.ok()) {
          const FieldDiff d = compareFields(ref, r.kept.field(r.result.grid), FieldTolerance::exact());
          if (d.ok) {
            ++correct;
          } else {
            ++wrong;
            verdict.fail(name, q.grid, "wrong field: " + d.describe());
          }
        } else if (r.result.status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
          ++exhausted;
        } else {
          ++failed;
          verdict.fail(name, q.grid, fmt::format("unexpected status {}: {}", int(r.result.status.error_code()),
                                                 r.result.status.error_message()));
        }
        r.kept = {};
      }
      if (correct + wrong == 0) verdict.fail(load_name, q.grid, "no query completed, so none was checked");
      md_load = fmt::format(
          "\n| load test | queries | max concurrent | correct | RESOURCE_EXHAUSTED | wrong | other errors | wall s | "
          "server RSS idle MB | server RSS peak MB (sampled) | server VmHWM MB |\n|---|---|---|---|---|---|---|---|---|---|---|\n"
          "| {} {}^3, limit {} voxels | {} | {} | {} | {} | {} | {} | {:.2f} | {:.0f} | {:.0f} | {:.0f} |\n",
          use_mesh ? "bunny" : "1 point", load_resolution, load_limit_voxels, concurrent, max_queries, correct,
          exhausted, wrong, failed, wall, idle_rss, peak_rss, hwm);
      out["load"] = {{"queries", concurrent}, {"max_concurrent", max_queries}, {"correct", correct},
                     {"resource_exhausted", exhausted}, {"wrong", wrong}, {"failed", failed},
                     {"wall_s", wall}, {"rss_idle_mb", idle_rss}, {"rss_peak_mb", peak_rss}, {"vmhwm_mb", hwm},
                     {"resolution", load_resolution}, {"limit_voxels", load_limit_voxels},
                     {"seeds", use_mesh ? "bunny" : "point"}};
    }
    fmt::print("## service_bench ({} compute threads, loopback)\n\n{}{}\n", threads, md, md_load);
  } catch (const std::exception& e) {
    verdict.fail("service_bench", e.what());
  }
  out["pass"] = verdict.ok();
  if (!json_path.empty()) distband::bench::writeResultFile(json_path, out.dump(2) + "\n");
  return verdict.finish();
}
