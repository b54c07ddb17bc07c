// service_bench: what the network path costs. Starts the real distband-server as a child process on loopback and,
// in the same run, the in-process engine on the same input:
//   1. full-domain N^3 queries (no limit; points, then the bunny mesh): time until the first segment's bricks reach
//      the client vs the whole query (goal <= 10 %), and the whole stream vs the in-process engine (goal <= 1.2x);
//   2. 16 concurrent queries against a server with --max-queries 4: every query completes with the reference
//      field (order-independent checksum) or gets RESOURCE_EXHAUSTED; the server's peak RSS is sampled from /proc.
// Output: a markdown table on stdout and a JSON file (--json).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include "bench/bench_util.h"
#include "tests/support/child_server.h"
#include "client/remote_client.h"
#include "core/band/band_engine.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/point_seeds.h"

namespace distband {
namespace {

using bench::Clock;
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

// ---- an order-independent checksum of a delivered field ----
struct FieldSum {
  uint64_t voxels = 0, hash = 0;
  void add(const SegmentBricks& s) {
    for (const Brick& b : s.bricks)
      for (int i = 0; i < kBrickVoxels; ++i)
        if (b.mask.test(i)) {
          const Coord c = b.origin + brickLocal(i);
          uint32_t bits;
          std::memcpy(&bits, &b.values[i], 4);
          uint64_t h = (uint64_t(uint32_t(c.x)) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(uint32_t(c.y)) << 21) ^
                       (uint64_t(uint32_t(c.z)) << 42) ^ (uint64_t(bits) * 0xC2B2AE3D27D4EB4Full);
          h ^= h >> 29;
          hash += h * 0xBF58476D1CE4E5B9ull;
          ++voxels;
        }
  }
  bool operator==(const FieldSum&) const = default;
};

struct Case {
  std::string name;
  v1::QueryRequest request;
  Grid grid;   // filled by the in-process side
  Seeds seeds;
  BandOptions options;
  double seed_seconds = 0;
};

struct InProcess {
  double seconds = 0;  ///< seeds + engine
  FieldSum sum;
};

InProcess runInProcess(const Case& c, const TriangleMesh* mesh, const MeshSeedOptions& mso, int threads) {
  InProcess r;
  const auto t0 = Clock::now();
  Seeds seeds;
  if (mesh) {
    if (Status e = makeMeshSeeds(c.grid, *mesh, mso, &seeds); !e.ok()) throw std::runtime_error(e.toString());
  } else {
    seeds = c.seeds;  // point seeds are trivial (27 voxels); copying them is not timed work of note
  }
  BandOptions o = c.options;
  o.threads = 0;
  tbb::task_arena arena(threads);
  std::vector<SegmentBricks> kept;  // checksummed after the clock stops: the engine alone is timed
  arena.execute([&] { computeBandField(c.grid, seeds, o, [&](SegmentBricks&& s) { kept.push_back(std::move(s)); }); });
  r.seconds = since(t0);
  for (const SegmentBricks& s : kept) r.sum.add(s);
  return r;
}

struct Remote {
  RemoteQueryResult result;
  FieldSum sum;
};

Remote runRemote(RemoteClient& client, const v1::QueryRequest& request, bool checksum) {
  Remote r;
  RemoteQueryCallbacks cb;
  std::vector<SegmentBricks> kept;  // decoded by the library while streaming; checksummed after the clock stops
  if (checksum)
    cb.on_bricks = [&](SegmentBricks&& b, uint64_t) {
      kept.push_back(std::move(b));
      return true;
    };
  r.result = client.query(request, cb);
  for (const SegmentBricks& s : kept) r.sum.add(s);
  return r;
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
  app.add_option("--json", json_path, "JSON output")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  nlohmann::json out;
  out["threads"] = threads;
  out["resolution"] = resolution;
  out["cases"] = nlohmann::json::array();
  std::string md = fmt::format(
      "| case | in-process s | stream s | stream / in-process | first bricks s | first / total | MB streamed | "
      "field equal |\n|---|---|---|---|---|---|---|---|\n");

  TriangleMesh mesh;
  bool have_mesh = false;
  std::string mesh_bytes;
  if (!mesh_path.empty()) {
    if (Status e = loadMesh(mesh_path, &mesh, nullptr); e.ok()) {
      have_mesh = true;
      std::ifstream in(mesh_path, std::ios::binary);
      mesh_bytes.assign(std::istreambuf_iterator<char>(in), {});
    } else {
      fmt::print(stderr, "skipping the mesh case: {}\n", e.toString());
    }
  }

  {
    ServerProcess server(server_bin, {"--threads", std::to_string(threads), "--max-queries", "4"});
    RemoteClient client(server.target());

    std::vector<Case> cases;
    {  // one point near a corner: the field grows over the whole domain, many segments
      Case c;
      c.name = fmt::format("1 point, {}^3, full domain", resolution);
      c.grid = Grid({0, 0, 0}, 1.0, {resolution, resolution, resolution});
      const Vec3d p{resolution * 0.3 + 0.25, resolution * 0.4 + 0.5, resolution * 0.35 + 0.1};
      makePointSeeds(c.grid, {p}, &c.seeds);
      c.options.segment_length_world = segment_voxels;
      v1::Vec3* v = c.request.mutable_points()->add_points();
      v->set_x(p.x);
      v->set_y(p.y);
      v->set_z(p.z);
      c.request.mutable_grid()->set_voxel_size(1.0);
      c.request.mutable_grid()->mutable_dims()->set_x(uint32_t(resolution));
      c.request.mutable_grid()->mutable_dims()->set_y(uint32_t(resolution));
      c.request.mutable_grid()->mutable_dims()->set_z(uint32_t(resolution));
      c.request.set_segment_length(segment_voxels);
      cases.push_back(std::move(c));
    }
    std::string mesh_id;
    if (have_mesh) {
      v1::UploadReply up;
      if (grpc::Status s = client.uploadMesh(mesh_bytes, meshFormatFromPath(mesh_path), "bunny", &up); !s.ok()) {
        fmt::print(stderr, "upload failed: {}\n", s.error_message());
        return 1;
      }
      mesh_id = up.asset_id();
      Case c;
      c.name = fmt::format("bunny, {}^3, full domain", resolution);
      MeshGridOptions mo;
      mo.resolution = resolution;
      (void)gridForMesh(mesh, mo, {}, &c.grid);
      c.options.segment_length_world = segment_voxels * c.grid.voxelSize();
      c.request.set_asset_id(mesh_id);
      c.request.mutable_grid()->set_resolution(uint32_t(resolution));
      c.request.set_segment_length(c.options.segment_length_world);
      cases.push_back(std::move(c));
    }

    for (Case& c : cases) {
      const bool is_mesh = c.request.has_asset_id();
      std::vector<double> inproc, stream, first;
      FieldSum ref;
      double mb = 0;
      bool equal = true;
      for (int i = 0; i < repeat; ++i) {
        const InProcess ip = runInProcess(c, is_mesh ? &mesh : nullptr, MeshSeedOptions{}, threads);
        inproc.push_back(ip.seconds);
        ref = ip.sum;
        const Remote rm = runRemote(client, c.request, true);
        if (!rm.result.status.ok()) {
          fmt::print(stderr, "{}: query failed: {}\n", c.name, rm.result.status.error_message());
          return 1;
        }
        stream.push_back(rm.result.total_seconds);
        first.push_back(rm.result.first_bricks_seconds);
        mb = rm.result.wire_bytes / 1e6;
        equal = equal && rm.sum == ip.sum;
        fmt::print(stderr, "{} run {}: in-process {:.3f}s, stream {:.3f}s (server compute {:.3f}s), first bricks {:.3f}s, "
                   "{} segments\n", c.name, i, ip.seconds, rm.result.total_seconds,
                   rm.result.summary.compute_seconds(), rm.result.first_bricks_seconds,
                   rm.result.summary.segments_size());
      }
      const double ip = bench::median(inproc), st = bench::median(stream), fb = bench::median(first);
      md += fmt::format("| {} | {:.3f} | {:.3f} | {:.2f}x | {:.3f} | {:.1f} % | {:.1f} | {} |\n", c.name, ip, st,
                        st / ip, fb, 100 * fb / st, mb, equal ? "yes" : "NO");
      out["cases"].push_back({{"case", c.name}, {"in_process_s", ip}, {"stream_s", st}, {"ratio", st / ip},
                              {"first_bricks_s", fb}, {"first_fraction", fb / st}, {"mb", mb},
                              {"segment_voxels", segment_voxels}, {"field_equal", equal},
                              {"in_process_runs", inproc}, {"stream_runs", stream}, {"first_runs", first}});
    }
  }

  // ---- load: concurrent queries on a server limited to max_queries ----
  std::string md_load;
  if (concurrent > 0) {
    ServerProcess server(server_bin,
                         {"--threads", std::to_string(threads), "--max-queries", std::to_string(max_queries)});
    RemoteClient client(server.target());
    v1::QueryRequest req;
    Case ref_case;
    const bool use_mesh = have_mesh;
    if (use_mesh) {
      v1::UploadReply up;
      client.uploadMesh(mesh_bytes, meshFormatFromPath(mesh_path), "bunny", &up);
      req.set_asset_id(up.asset_id());
      req.mutable_grid()->set_resolution(uint32_t(load_resolution));
      MeshGridOptions mo;
      mo.resolution = load_resolution;
      (void)gridForMesh(mesh, mo, {}, &ref_case.grid);
    } else {
      ref_case.grid = Grid({0, 0, 0}, 1.0, {load_resolution, load_resolution, load_resolution});
      const Vec3d p{load_resolution * 0.5, load_resolution * 0.5, load_resolution * 0.5};
      makePointSeeds(ref_case.grid, {p}, &ref_case.seeds);
      v1::Vec3* v = req.mutable_points()->add_points();
      v->set_x(p.x);
      v->set_y(p.y);
      v->set_z(p.z);
      req.mutable_grid()->set_voxel_size(1.0);
      req.mutable_grid()->mutable_dims()->set_x(uint32_t(load_resolution));
      req.mutable_grid()->mutable_dims()->set_y(uint32_t(load_resolution));
      req.mutable_grid()->mutable_dims()->set_z(uint32_t(load_resolution));
    }
    const double h = ref_case.grid.voxelSize();
    req.set_limit(load_limit_voxels * h);
    req.set_segment_length(4 * h);
    ref_case.options.limit_world = load_limit_voxels * h;
    ref_case.options.segment_length_world = 4 * h;
    MeshSeedOptions mso;
    mso.limit_voxels = load_limit_voxels;
    const InProcess ref = runInProcess(ref_case, use_mesh ? &mesh : nullptr, mso, threads);

    const double idle_rss = server.rssMb();
    std::atomic<bool> sampling{true};
    double peak_rss = idle_rss;
    std::thread sampler([&] {
      while (sampling) {
        peak_rss = std::max(peak_rss, server.rssMb());
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    });
    std::atomic<int> correct{0}, exhausted{0}, wrong{0}, failed{0};
    std::vector<std::thread> clients;
    const auto t0 = Clock::now();
    for (int i = 0; i < concurrent; ++i)
      clients.emplace_back([&] {
        Remote r = runRemote(client, req, true);
        if (r.result.status.ok()) (r.sum == ref.sum ? correct : wrong)++;
        else if (r.result.status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) exhausted++;
        else failed++;
      });
    for (auto& t : clients) t.join();
    const double wall = since(t0);
    sampling = false;
    sampler.join();
    const double hwm = server.rssMb("VmHWM:");
    md_load = fmt::format(
        "\n| load test | queries | max concurrent | correct | RESOURCE_EXHAUSTED | wrong | other errors | wall s | "
        "server RSS idle MB | server RSS peak MB (sampled) | server VmHWM MB |\n|---|---|---|---|---|---|---|---|---|---|---|\n"
        "| {} {}^3, limit {} voxels | {} | {} | {} | {} | {} | {} | {:.2f} | {:.0f} | {:.0f} | {:.0f} |\n",
        use_mesh ? "bunny" : "1 point", load_resolution, load_limit_voxels, concurrent, max_queries, correct.load(),
        exhausted.load(), wrong.load(), failed.load(), wall, idle_rss, peak_rss, hwm);
    out["load"] = {{"queries", concurrent}, {"max_concurrent", max_queries}, {"correct", correct.load()},
                   {"resource_exhausted", exhausted.load()}, {"wrong", wrong.load()}, {"failed", failed.load()},
                   {"wall_s", wall}, {"rss_idle_mb", idle_rss}, {"rss_peak_mb", peak_rss}, {"vmhwm_mb", hwm},
                   {"resolution", load_resolution}, {"limit_voxels", load_limit_voxels},
                   {"seeds", use_mesh ? "bunny" : "point"}};
  }

  fmt::print("## service_bench ({} compute threads, loopback)\n\n{}{}\n", threads, md, md_load);
  if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  return 0;
}
