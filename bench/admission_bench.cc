// admission_bench: does the server's admission estimate (server/request_validation.cc -> core/field/field_memory.h)
// stay above what a query really uses? For each case the query is resolved by the server's own path
// (bench/server_reference.h: an inline mesh parsed by the server's parser, then resolveQuery), then run in a child
// process through the server's own QueryJob (seeds, engine, encoding, the bounded queue drained by the parent
// thread), and the child's peak RSS growth during the run is compared with the estimate.
// Reference: none for the field (this bench measures memory; the field itself is what the server's QueryJob makes).
// Pass: every query completes (exit 1 otherwise, naming the case); goal (exit 3): every measured peak below its
// estimate. --smoke runs the three small cases (points, a signed shell volume, the bunny) and writes no results file.
//
//   build/bench/admission_bench [--cases all|NAME,...] [--threads 2] [--mesh-dir DIR] [--tag NAME] [--smoke]
//
// Output: one row per case (grid, limit, touched-voxel bound, delivered voxels, estimate, measured peak, ratio) to
// stdout and bench/results/<tag>.md. A ratio above 1 would mean the server can be pushed past its budget.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "bench/server_reference.h"
#include "core/interrupter.h"
#include "server/memory_budget.h"
#include "server/query_job.h"
#include "server/request_validation.h"
#include "tests/support/query_requests.h"

namespace distband {
namespace {

struct Case {
  std::string name;
  std::function<v1::QueryRequest()> request;
};

uint64_t statusKb(const char* key) {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind(key, 0) == 0) return std::stoull(line.substr(std::string(key).size()));
  return 0;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

v1::QueryRequest points(std::vector<Vec3d> pts, int n, double limit) {
  return pointsRequest(pts, {n, n, n}, 1.0, 0, limit);
}

v1::QueryRequest volume(const std::vector<uint8_t>& mask, int n, bool signed_field, double limit) {
  v1::QueryRequest r;
  r.mutable_volume()->mutable_dims()->set_x(uint32_t(n));
  r.mutable_volume()->mutable_dims()->set_y(uint32_t(n));
  r.mutable_volume()->mutable_dims()->set_z(uint32_t(n));
  r.mutable_volume()->set_mask(std::string(mask.begin(), mask.end()));
  r.mutable_grid()->set_voxel_size(1);
  r.set_sign(signed_field ? v1::SIGN_MODE_MASK_INSIDE : v1::SIGN_MODE_UNSIGNED);
  r.set_limit(limit);
  return r;
}

v1::QueryRequest mesh(const std::string& path, int resolution, double half_width_voxels, v1::PropagationMode mode,
                      v1::SignMode sign) {
  v1::QueryRequest r;
  r.mutable_mesh()->set_format(path.ends_with(".off") ? v1::MESH_FORMAT_OFF : v1::MESH_FORMAT_OBJ);
  r.mutable_mesh()->set_data(readFile(path));
  r.mutable_grid()->set_resolution(uint32_t(resolution));
  r.set_mode(mode);
  r.set_sign(sign);
  if (half_width_voxels > 0) r.set_limit_voxels(half_width_voxels);  // 0: no limit
  return r;
}

/// Resolves as the server does (bench/server_reference.h: an inline mesh is parsed first).
Status resolve(const v1::QueryRequest& request, const ServerOptions& options, ResolvedQuery* q) {
  bench::ServerReference server(options);
  return server.resolve(request, q);
}

struct Measured {
  double peak_bytes = 0, seconds = 0;
  uint64_t voxels = 0;
  bool ok = false;
};

/// The child's side: runs the query through QueryJob and prints "peak_bytes voxels seconds ok".
int measure(const Case& c, const ServerOptions& options, int threads) {
  ResolvedQuery q;
  if (Status s = resolve(c.request(), options, &q); !s.ok()) {
    std::cerr << c.name << ": " << s.toString() << "\n";
    return 1;
  }
  tbb::task_arena arena(threads + 1, 1);
  { std::ofstream("/proc/self/clear_refs") << "5"; }  // reset the peak (VmHWM) to the current RSS
  const uint64_t base_kb = statusKb("VmRSS:");
  Interrupter interrupter;
  const auto t0 = std::chrono::steady_clock::now();
  QueryJob job(std::move(q), &arena, options.stream_buffer_bytes, &interrupter);
  job.start();
  QueryJob::Message msg;
  while (job.queue().pop(&msg, std::chrono::milliseconds(50)) != BoundedQueue<QueryJob::Message>::PopResult::kClosed)
    msg.reset();
  job.join();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%.0f %lld %.3f %d\n", double(statusKb("VmHWM:") - base_kb) * 1024.0, (long long)job.result().voxels,
              seconds, job.status().ok() ? 1 : 0);
  return 0;
}

/// Runs `self --child NAME` (a fresh process: its peak RSS is the query's alone) and reads its line.
Measured runInChild(const std::string& self, const Case& c, const std::string& mesh_dir, int threads) {
  Measured m;
  auto [out, rc] = bench::runCommand(fmt::format("'{}' --child {} --threads {} --mesh-dir '{}'", self, c.name,
                                                 threads, mesh_dir));
  long long voxels = 0;
  int ok = 0;
  if (rc == 0 && std::sscanf(out.c_str(), "%lf %lld %lf %d", &m.peak_bytes, &voxels, &m.seconds, &ok) == 4) {
    m.voxels = uint64_t(voxels);
    m.ok = ok == 1;
  }
  return m;
}

int run(int argc, char** argv) {
  std::string cases_arg = "all", mesh_dir = std::string(DISTBAND_BENCH_DIR) + "/../tests/data/meshes", tag = "admission_bench";
  int threads = 2;
  std::string child;
  CLI::App app{"admission_bench: the server's memory estimate vs the measured peak of each query"};
  app.add_option("--cases", cases_arg, "all, or a comma-separated list of case names");
  app.add_option("--threads", threads, "compute threads of the query")->capture_default_str();
  app.add_option("--mesh-dir", mesh_dir, "directory with bunny.obj, fandisk.off, teapot.obj (armadillo.off if present)");
  app.add_option("--tag", tag, "output name under bench/results/");
  app.add_option("--child", child, "(internal) measure one case in this process");
  bool smoke = false;
  app.add_flag("--smoke", smoke, "the small cases only (the CTest run); writes no results file");
  CLI11_PARSE(app, argc, argv);
  if (smoke) cases_arg = "points_1_64_unlimited,shell_64_signed_limit3,bunny_64_exact_hw3";

  // Made on first use: the parent only estimates, each child builds its own input.
  auto shell256 = [] { return bench::sphereShellMask(256); };
  auto blobs256 = [] { return bench::randomBlobsMask(256); };
  const double inf = 0;  // 0 = no limit
  std::vector<Case> cases = {
      {"points_1_64_unlimited", [&] { return points({{20.5, 30.25, 40}}, 64, inf); }},
      {"shell_64_signed_limit3", [&] { return volume(bench::sphereShellMask(64), 64, true, 3); }},
      {"bunny_64_exact_hw3",
       [&] { return mesh(mesh_dir + "/bunny.obj", 64, 3, v1::PROPAGATION_MODE_EXACT, v1::SIGN_MODE_PSEUDONORMAL); }},
      {"points_1_256_unlimited", [&] { return points({{128, 128, 128}}, 256, inf); }},
      {"points_2_384_unlimited", [&] { return points({{128, 128, 128}, {255, 255, 255}}, 384, inf); }},
      {"points_1_512_limit10", [&] { return points({{200, 300, 256}}, 512, 10); }},
      {"points_100_512_limit5",
       [&] {
         std::vector<Vec3d> p;
         for (int i = 0; i < 100; ++i) p.push_back({double(17 + 97 * i % 480), double(31 + 53 * i % 470), double(5 + 211 * i % 500)});
         return points(p, 512, 5);
       }},
      {"shell_256_unsigned", [&] { return volume(shell256(), 256, false, inf); }},
      {"shell_256_signed", [&] { return volume(shell256(), 256, true, inf); }},
      {"shell_256_signed_limit5", [&] { return volume(shell256(), 256, true, 5); }},
      {"blobs_256_unsigned", [&] { return volume(blobs256(), 256, false, inf); }},
      {"blobs_256_signed_limit5", [&] { return volume(blobs256(), 256, true, 5); }},
      {"bunny_256_exact_unlimited",
       [&] { return mesh(mesh_dir + "/bunny.obj", 256, 0, v1::PROPAGATION_MODE_EXACT, v1::SIGN_MODE_PSEUDONORMAL); }},
      {"bunny_512_exact_hw3",
       [&] { return mesh(mesh_dir + "/bunny.obj", 512, 3, v1::PROPAGATION_MODE_EXACT, v1::SIGN_MODE_PSEUDONORMAL); }},
      {"bunny_256_paper_hw20",
       [&] { return mesh(mesh_dir + "/bunny.obj", 256, 20, v1::PROPAGATION_MODE_PAPER, v1::SIGN_MODE_PSEUDONORMAL); }},
      {"fandisk_384_exact_hw20_parity",
       [&] { return mesh(mesh_dir + "/fandisk.off", 384, 20, v1::PROPAGATION_MODE_EXACT, v1::SIGN_MODE_PARITY); }},
      {"teapot_256_exact_hw3_winding",
       [&] { return mesh(mesh_dir + "/teapot.obj", 256, 3, v1::PROPAGATION_MODE_EXACT, v1::SIGN_MODE_WINDING); }},
  };
  if (std::ifstream(mesh_dir + "/armadillo.off"))
    cases.push_back({"armadillo_1024_exact_hw3", [&] {
                       return mesh(mesh_dir + "/armadillo.off", 1024, 3, v1::PROPAGATION_MODE_EXACT,
                                   v1::SIGN_MODE_PSEUDONORMAL);
                     }});

  ServerOptions options;
  if (!child.empty()) {
    for (const Case& c : cases)
      if (c.name == child) return measure(c, options, threads);
    std::cerr << "unknown case " << child << "\n";
    return 2;
  }
  const std::string self = argv[0];
  std::ostringstream md;
  md << fmt::format("# admission_bench ({} threads)\n\nEstimate = what the server reserves (seeds + engine + one output "
                    "chunk + the {} stream buffer); measured = the child's peak RSS growth during the query.\n\n",
                    threads, humanBytes(options.stream_buffer_bytes));
  md << "| case | grid | touched bound | delivered | estimate | measured | measured / estimate | s |\n"
        "|---|---|---|---|---|---|---|---|\n";
  std::cout << md.str();
  bool all_under = true;
  for (const Case& c : cases) {
    if (cases_arg != "all" && ("," + cases_arg + ",").find("," + c.name + ",") == std::string::npos) continue;
    ResolvedQuery q;
    if (Status s = resolve(c.request(), options, &q); !s.ok()) {
      std::cerr << c.name << ": " << s.toString() << "\n";
      return 1;
    }
    const double estimate = double(q.memory.total() + options.stream_buffer_bytes);
    const Measured m = runInChild(self, c, mesh_dir, threads);
    if (!m.ok) {
      std::cerr << "admission_bench: FAIL " << c.name << ": the query failed in the child\n";
      return bench::kExitWrong;
    }
    const double ratio = m.peak_bytes / estimate;
    all_under = all_under && ratio <= 1.0;
    const std::string row =
        fmt::format("| {} | {}x{}x{} | {} | {} | {} ({}) | {} | {:.2f} | {:.2f} |\n", c.name, q.grid.dims().x,
                    q.grid.dims().y, q.grid.dims().z, q.touched_voxels_bound, m.voxels, humanBytes(uint64_t(estimate)),
                    q.memory.summary(), humanBytes(uint64_t(m.peak_bytes)), ratio, m.seconds);
    std::cout << row << std::flush;
    md << row;
  }
  md << fmt::format("\n{}\n", all_under ? "Every measured peak is below its estimate."
                                        : "**Some measured peak exceeds its estimate.**");
  if (!smoke) distband::bench::writeResultFile(std::string(DISTBAND_BENCH_DIR) + "/results/" + tag + ".md", md.str());
  return all_under ? 0 : 3;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) { return distband::run(argc, argv); }
