// whole_process_bench: `distband compute --mesh` against OpenVDB as whole processes (issue 11, goal 6): wall time
// from exec to exit of each, loading the mesh, computing the narrow band and writing the .vdb.
// Contract:
//   * Per mesh, resolution and thread count: runs `distband compute --mesh F --resolution N --limit-voxels W
//     --threads T --out D.vdb` and the peer `openvdb_mesh_process --mesh F --resolution N --half-width W --threads T
//     --out P.vdb` (bench/openvdb_mesh_process.cc: the same reader, grid and transform, then
//     meshToSignedDistanceField and io::File) as child processes (fork + execv), alternating which goes first per rep,
//     after one untimed warm-up run of each (page cache, so both read the executables and the mesh from memory).
//   * Timed: wall seconds from fork to wait4's return, and the child's CPU seconds (user + system, from wait4's
//     rusage: all its threads). Reported: medians of --reps, and the ratio distband / OpenVDB of each.
//   * distband's own phase lines ("engine ... s, total ... s (write ... s)") are read from its stdout, so the
//     in-process part can be told from process start-up and exit: load+seeds = total - engine - write (mesh read,
//     grid, plan, seeds, output set-up), start+exit = wall - total (exec, dynamic loading, static initialisers,
//     argument parsing, destructors, exit).
//   * The same job: both files are read back once per row and compared — active voxels of each, voxels active in
//     both, the largest |difference| over those in voxels, and how many of them disagree in sign.
//   * --peer-env NAME=VALUE sets the peer's environment (e.g. the malloc tunable distband sets in its main()).
//   * Output: a Markdown table on stdout (and <out-dir>/<tag>.md), and with --json the rows as JSON.
//     Files go to a fresh temporary directory, removed at the end.
#include <sys/resource.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>

#include "bench/bench_util.h"
#include "tests/support/vdb_reader.h"

#ifndef DISTBAND_CLI_BIN
#define DISTBAND_CLI_BIN "distband"
#endif
#ifndef DISTBAND_PEER_BIN
#define DISTBAND_PEER_BIN "openvdb_mesh_process"
#endif

namespace distband {
namespace {

using json = nlohmann::json;
using bench::median;
using bench::Clock;
using bench::since;

struct ChildRun {
  double wall_s = 0, cpu_s = 0;
  double max_rss_mb = 0;
  int status = -1;
};

// Runs argv[0] with its stdout in `stdout_path` (stderr inherited) and `env` (NAME=VALUE) added to its environment,
// waiting for it with its rusage.
ChildRun runChild(const std::vector<std::string>& args, const std::string& stdout_path,
                  const std::vector<std::string>& env = {}) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  ChildRun r;
  const auto t0 = Clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    const int fd = open(stdout_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, STDOUT_FILENO);
      close(fd);
    }
    for (const std::string& e : env) putenv(const_cast<char*>(e.c_str()));
    execv(argv[0], argv.data());
    _exit(127);
  }
  if (pid < 0) return r;
  int status = 0;
  rusage ru{};
  wait4(pid, &status, 0, &ru);
  r.wall_s = since(t0);
  r.cpu_s = ru.ru_utime.tv_sec + 1e-6 * ru.ru_utime.tv_usec + ru.ru_stime.tv_sec + 1e-6 * ru.ru_stime.tv_usec;
  r.max_rss_mb = ru.ru_maxrss / 1024.0;
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The number after `key` in distband's "done:" line (NAN when absent).
double phaseSeconds(const std::string& log, const std::string& key) {
  const size_t done = log.rfind("done:");
  if (done == std::string::npos) return NAN;
  const size_t p = log.find(key, done);
  return p == std::string::npos ? NAN : std::atof(log.c_str() + p + key.size());
}

struct Agreement {
  int64_t distband_active = 0, openvdb_active = 0, both_active = 0, sign_disagree = 0;
  double max_diff_vox = 0;
};

std::string compareFiles(const std::string& a_path, const std::string& b_path, double voxel_size, Agreement* out) {
  openvdb::FloatGrid::Ptr a, b;
  if (std::string e = readVdb(a_path, &a); !e.empty()) return e;
  if (std::string e = readVdb(b_path, &b); !e.empty()) return e;
  Agreement g;
  g.distband_active = int64_t(a->activeVoxelCount());
  g.openvdb_active = int64_t(b->activeVoxelCount());
  auto bacc = b->getConstAccessor();
  for (auto it = a->cbeginValueOn(); it; ++it) {
    float vb;
    if (!bacc.probeValue(it.getCoord(), vb)) continue;
    ++g.both_active;
    const float va = *it;
    g.max_diff_vox = std::max(g.max_diff_vox, std::abs(double(va) - vb) / voxel_size);
    // Voxels on the surface itself may round either way; a disagreement farther than 0.5 voxels is a real one.
    if ((va < 0) != (vb < 0) && std::min(std::abs(va), std::abs(vb)) > 0.5 * voxel_size) ++g.sign_disagree;
  }
  *out = g;
  return {};
}

double voxelSizeOf(const std::string& path) {
  openvdb::FloatGrid::Ptr g;
  if (!readVdb(path, &g).empty()) return NAN;
  return g->voxelSize()[0];
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"distband compute --mesh vs OpenVDB (read, meshToSignedDistanceField, write) as whole processes"};
  std::string mesh_dir = "/work/shared/data/meshes";
  std::vector<std::string> meshes = {"armadillo.off", "bunny.obj", "fandisk.off", "teapot.obj"};
  std::vector<int> resolutions = {256};
  std::vector<int> threads = {2};
  int half_width = 3, reps = 5;
  std::string distband_bin = DISTBAND_CLI_BIN, peer_bin = DISTBAND_PEER_BIN;
  std::string out_dir = DISTBAND_BENCH_DIR "/results", tag, json_path;
  std::vector<std::string> peer_env;
  app.add_option("--mesh-dir", mesh_dir);
  app.add_option("--meshes", meshes)->delimiter(',');
  app.add_option("--resolutions", resolutions)->delimiter(',');
  app.add_option("--threads", threads, "thread counts (each row runs both with the same count)")->delimiter(',');
  app.add_option("--half-width", half_width, "narrow band half-width in voxels (distband --limit-voxels)");
  app.add_option("--reps,-R", reps);
  app.add_option("--distband", distband_bin);
  app.add_option("--peer", peer_bin);
  app.add_option("--peer-env", peer_env,
                 "NAME=VALUE added to the peer's environment (e.g. GLIBC_TUNABLES=glibc.malloc.top_pad=67108864, to "
                 "give it distband's malloc setting)");
  app.add_option("--out-dir", out_dir);
  app.add_option("--tag", tag, "also write <out-dir>/<tag>.md");
  app.add_option("--json", json_path, "write the rows as JSON to this file");
  CLI11_PARSE(app, argc, argv);
  openvdb::initialize();

  char tmpl[] = "/tmp/whole_process_bench.XXXXXX";
  const char* dir_c = mkdtemp(tmpl);
  if (!dir_c) {
    std::fprintf(stderr, "cannot create a temporary directory\n");
    return 1;
  }
  const std::string dir = dir_c;
  const std::string dist_out = dir + "/distband.vdb", peer_out = dir + "/openvdb.vdb";
  const std::string dist_log = dir + "/distband.log", peer_log = dir + "/openvdb.log";

  std::string md = fmt::format(
      "Whole process, exec to exit (read mesh, narrow band half-width {} voxels, write .vdb); medians of {} "
      "alternating runs; CPU = user + system of the child (all threads).\n\n"
      "| mesh | res | threads | distband s | OpenVDB s | ratio | distband CPU s | OpenVDB CPU s | CPU ratio | "
      "distband load+seeds s | distband engine s | distband write s | distband start+exit s | active voxels distband / OpenVDB | max diff (vox) | sign diff |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      half_width, reps);
  std::fputs(md.c_str(), stdout);
  std::fflush(stdout);
  json rows = json::array();
  int failures = 0;
  for (int res : resolutions)
    for (const std::string& mesh : meshes)
      for (int t : threads) {
        const std::string mesh_path = mesh_dir + "/" + mesh;
        const std::vector<std::string> dist_args = {distband_bin,        "compute",        "--mesh",
                                                    mesh_path,           "--resolution",   std::to_string(res),
                                                    "--limit-voxels",    std::to_string(half_width),
                                                    "--threads",         std::to_string(t), "--out", dist_out};
        const std::vector<std::string> peer_args = {peer_bin,      "--mesh",       mesh_path,
                                                    "--resolution", std::to_string(res), "--half-width",
                                                    std::to_string(half_width), "--threads", std::to_string(t),
                                                    "--out",        peer_out};
        // Warm-up (untimed), then the check that both did the same job.
        const ChildRun w1 = runChild(dist_args, dist_log), w2 = runChild(peer_args, peer_log, peer_env);
        if (w1.status != 0 || w2.status != 0) {
          std::fprintf(stderr, "%s %d^3: a child failed (distband %d, openvdb %d)\n", mesh.c_str(), res, w1.status,
                       w2.status);
          ++failures;
          continue;
        }
        Agreement agree;
        const double h = voxelSizeOf(peer_out);
        if (std::string e = compareFiles(dist_out, peer_out, h, &agree); !e.empty()) {
          std::fprintf(stderr, "%s\n", e.c_str());
          ++failures;
          continue;
        }
        std::vector<double> dw, dc, pw, pc, engine, write, before_engine, outside_main;
        for (int r = 0; r < reps; ++r) {
          auto runDistband = [&] {
            const ChildRun c = runChild(dist_args, dist_log);
            if (c.status != 0) ++failures;
            dw.push_back(c.wall_s);
            dc.push_back(c.cpu_s);
            const std::string log = readText(dist_log);
            engine.push_back(phaseSeconds(log, "engine "));
            write.push_back(phaseSeconds(log, "(write "));
            const double total = phaseSeconds(log, "total ");  // runCompute's clock: after start-up, before exit
            before_engine.push_back(total - engine.back() - write.back());
            outside_main.push_back(c.wall_s - total);
          };
          auto runPeer = [&] {
            const ChildRun c = runChild(peer_args, peer_log, peer_env);
            if (c.status != 0) ++failures;
            pw.push_back(c.wall_s);
            pc.push_back(c.cpu_s);
          };
          if (r % 2 == 0) {
            runDistband();
            runPeer();
          } else {
            runPeer();
            runDistband();
          }
        }
        const double dwm = median(dw), pwm = median(pw), dcm = median(dc), pcm = median(pc);
        const std::string line = fmt::format(
            "| {} | {}³ | {} | {:.3f} | {:.3f} | **{:.2f}×** | {:.3f} | {:.3f} | {:.2f}× | {:.3f} | {:.3f} | {:.3f} | "
            "{:.3f} | {} / {} | {:.3f} | {} |\n",
            mesh, res, t, dwm, pwm, dwm / pwm, dcm, pcm, dcm / pcm, median(before_engine), median(engine),
            median(write), median(outside_main),
            agree.distband_active, agree.openvdb_active, agree.max_diff_vox, agree.sign_disagree);
        md += line;
        std::fputs(line.c_str(), stdout);
        std::fflush(stdout);
        rows.push_back({{"mesh", mesh},
                        {"resolution", res},
                        {"half_width", half_width},
                        {"threads", t},
                        {"reps", reps},
                        {"distband_wall_s", dwm},
                        {"openvdb_wall_s", pwm},
                        {"ratio_wall", dwm / pwm},
                        {"distband_cpu_s", dcm},
                        {"openvdb_cpu_s", pcm},
                        {"ratio_cpu", dcm / pcm},
                        {"distband_engine_s", median(engine)},
                        {"distband_write_s", median(write)},
                        {"distband_load_seeds_s", median(before_engine)},
                        {"distband_startup_exit_s", median(outside_main)},
                        {"distband_wall_times_s", dw},
                        {"openvdb_wall_times_s", pw},
                        {"distband_cpu_times_s", dc},
                        {"openvdb_cpu_times_s", pc},
                        {"distband_active", agree.distband_active},
                        {"openvdb_active", agree.openvdb_active},
                        {"both_active", agree.both_active},
                        {"max_diff_vox", agree.max_diff_vox},
                        {"sign_disagree", agree.sign_disagree}});
      }
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  char when[64];
  const std::time_t now = std::time(nullptr);
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  std::string env_text;
  for (const std::string& e : peer_env) env_text += " " + e;
  const std::string footer = fmt::format("\n{}; distband {}; peer {}{}; {} cores online.\n", when, distband_bin,
                                         peer_bin, env_text.empty() ? "" : " with" + env_text,
                                         sysconf(_SC_NPROCESSORS_ONLN));
  md += footer;
  std::fputs(footer.c_str(), stdout);
  if (!tag.empty()) std::ofstream(out_dir + "/" + tag + ".md") << md;
  if (!json_path.empty()) std::ofstream(json_path) << json({{"rows", rows}}).dump(2) << "\n";
  return failures == 0 ? 0 : 1;
}
