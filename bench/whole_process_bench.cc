// whole_process_bench: `distband compute --mesh` against OpenVDB as whole processes: wall time from exec to exit of
// each, loading the mesh, computing the narrow band and writing the .vdb.
// Contract:
//   * Per mesh, resolution and thread count: runs `distband compute --mesh F --resolution N --limit-voxels W
//     --threads T --out D.vdb` and the peer `openvdb_mesh_process --mesh F --voxel-size H --origin X,Y,Z --dims
//     NX,NY,NZ --half-width W' --threads T --out P.vdb` (bench/openvdb_mesh_process.cc: the same reader, then
//     meshToSignedDistanceField and io::File) as child processes (fork + execv), alternating which goes first per rep,
//     after one untimed warm-up run of each (page cache, so both read the executables and the mesh from memory).
//   * The peer runs on distband's grid as distband's CLI planned it: the warm-up run of distband also writes --meta,
//     whose origin, voxel size, dims and limit (W' = limit / voxel size) are passed to the peer. Nothing here derives
//     a grid or a padding.
//   * Timed: wall seconds from fork to wait4's return, and the child's CPU seconds (user + system, from wait4's
//     rusage: all its threads), and each child's peak RSS (rusage's ru_maxrss, the largest over the timed runs).
//     Reported: medians of --reps, and the ratio distband / OpenVDB of each.
//   * distband's own phase lines ("engine ... s, total ... s (write ... s)") are read from its stdout, so the
//     in-process part can be told from process start-up and exit: load+seeds = total - engine - write (mesh read,
//     grid, plan, seeds, output set-up), start+exit = wall - total (exec, dynamic loading, static initialisers,
//     argument parsing, destructors, exit).
//   * Reference and pass: both files are read back after the warm-up and must be the same job (compareFiles): the
//     planned transform and dims exactly in both, the planned half-width as both backgrounds, 99.9 % of the voxels
//     both deliver within a voxel of each other in |distance|, on a closed mesh at most 0.01 % of them of opposite
//     sign farther than 0.5 voxel from the surface, and 97 % of each file's active voxels shared. Reported: active
//     voxels of each, the largest |difference| over the shared ones in voxels, sign disagreements. A failed child or
//     a mismatch is printed (row and the first disagreeing voxel) and makes the exit status 1.
//   * --peer-env NAME=VALUE sets the peer's environment (e.g. the malloc tunable distband sets in its main()).
//   * --smoke: tests/data's meshes at 64^3, 2 threads, one timed rep (the CTest run).
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
#include "bench/planned_field.h"
#include "core/mesh/triangle_mesh.h"
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

// What distband planned, read from its --meta output: the grid and the limit.
struct PlannedGrid {
  Coord dims{};
  Vec3d origin;
  double voxel_size = 0, limit_world = 0;
  double halfWidthVoxels() const { return limit_world / voxel_size; }
};

std::string readPlannedGrid(const std::string& meta_path, PlannedGrid* out) {
  const nlohmann::json m = nlohmann::json::parse(readText(meta_path), nullptr, false);
  if (m.is_discarded() || !m.contains("dims") || !m.contains("origin") || !m.contains("voxel_size") ||
      !m["limit"].is_number())
    return meta_path + ": not distband's field metadata with dims, origin, voxel_size and a finite limit";
  out->dims = {m["dims"][0].get<int>(), m["dims"][1].get<int>(), m["dims"][2].get<int>()};
  out->origin = {m["origin"][0].get<double>(), m["origin"][1].get<double>(), m["origin"][2].get<double>()};
  out->voxel_size = m["voxel_size"].get<double>();
  out->limit_world = m["limit"].get<double>();
  return {};
}

// The two files are the same job when (checked by compareFiles, thresholds in kAgreement*):
//   * both grids have distband's planned transform exactly (voxel size and origin) and its dims ("distband_dims");
//   * both backgrounds are the planned limit (the same half-width), within float rounding;
//   * of the voxels both deliver, at least kAgreementNearFraction have | |a| - |b| | <= 1 voxel (OpenVDB's own error
//     reaches ~1.2 voxel on a few voxels, distband's 0.15: docs/benchmarks.md);
//   * on a closed mesh, at most kAgreementSignFraction of them disagree in sign farther than 0.5 voxel from the
//     surface (an open mesh's inside is not defined the same way by both: the teapot's signs are reported only);
//   * each file's active voxels are at least kAgreementSharedFraction shared with the other's.
// A different grid, band or mesh breaks these by orders of magnitude; OpenVDB's scattered errors do not.
constexpr double kAgreementNearFraction = 0.999, kAgreementSignFraction = 1e-4, kAgreementSharedFraction = 0.97;

struct Agreement {
  int64_t distband_active = 0, openvdb_active = 0, both_active = 0, sign_disagree = 0, far = 0;
  double max_diff_vox = 0;
  std::string mismatch;  // "" when the files are the same job
};

std::string gridMismatch(const char* who, const openvdb::FloatGrid& g, const PlannedGrid& p) {
  // The map's own parameters (voxelSize() recomputes the scale and may differ in the last bit).
  openvdb::Vec3d v(-1), o(0);
  const openvdb::math::Transform& t = g.transform();
  if (auto m = t.constMap<openvdb::math::UniformScaleTranslateMap>()) {
    v = m->getScale();
    o = m->getTranslation();
  } else if (auto m2 = t.constMap<openvdb::math::ScaleTranslateMap>()) {
    v = m2->getScale();
    o = m2->getTranslation();
  }
  if (v[0] != p.voxel_size || v[1] != p.voxel_size || v[2] != p.voxel_size || o[0] != p.origin.x ||
      o[1] != p.origin.y || o[2] != p.origin.z)
    return fmt::format("{}'s transform (voxel size {:.17g}, origin {:.17g}, {:.17g}, {:.17g}) is not the planned grid's "
                       "(voxel size {:.17g}, origin {:.17g}, {:.17g}, {:.17g})",
                       who, v[0], o[0], o[1], o[2], p.voxel_size, p.origin.x, p.origin.y, p.origin.z);
  const openvdb::Vec3i d = g.metaValue<openvdb::Vec3i>("distband_dims");
  if (d != openvdb::Vec3i(p.dims.x, p.dims.y, p.dims.z))
    return fmt::format("{}'s dims {}x{}x{} are not the planned {}x{}x{}", who, d[0], d[1], d[2], p.dims.x, p.dims.y,
                       p.dims.z);
  if (std::abs(double(g.background()) - p.limit_world) > 1e-6 * p.limit_world)
    return fmt::format("{}'s background {:.9g} is not the planned limit {:.9g}", who, g.background(), p.limit_world);
  return {};
}

std::string compareFiles(const std::string& a_path, const std::string& b_path, const PlannedGrid& planned, bool closed,
                         Agreement* out) {
  openvdb::FloatGrid::Ptr a, b;
  if (std::string e = readVdb(a_path, &a); !e.empty()) return e;
  if (std::string e = readVdb(b_path, &b); !e.empty()) return e;
  Agreement g;
  try {
    g.mismatch = gridMismatch("distband", *a, planned);
    if (g.mismatch.empty()) g.mismatch = gridMismatch("OpenVDB", *b, planned);
  } catch (const std::exception& e) {
    g.mismatch = std::string("a file lacks the distband_dims metadata: ") + e.what();
  }
  const double h = planned.voxel_size;
  g.distband_active = int64_t(a->activeVoxelCount());
  g.openvdb_active = int64_t(b->activeVoxelCount());
  auto bacc = b->getConstAccessor();
  std::string first_sign, first_far;
  for (auto it = a->cbeginValueOn(); it; ++it) {
    float vb;
    if (!bacc.probeValue(it.getCoord(), vb)) continue;  // true when active
    ++g.both_active;
    const float va = *it;
    g.max_diff_vox = std::max(g.max_diff_vox, std::abs(double(va) - vb) / h);
    const openvdb::Coord c = it.getCoord();
    if (std::abs(std::abs(double(va)) - std::abs(double(vb))) > h && g.far++ == 0)
      first_far = fmt::format("({}, {}, {}): distband {:.6g}, OpenVDB {:.6g}", c.x(), c.y(), c.z(), va, vb);
    // Voxels on the surface itself may round either way; a disagreement farther than 0.5 voxels is a real one.
    if ((va < 0) != (vb < 0) && std::min(std::abs(va), std::abs(vb)) > 0.5 * h && g.sign_disagree++ == 0)
      first_sign = fmt::format("({}, {}, {}): distband {:.6g}, OpenVDB {:.6g}", c.x(), c.y(), c.z(), va, vb);
  }
  if (g.mismatch.empty()) {
    const double both = double(std::max<int64_t>(1, g.both_active));
    if (double(g.far) > (1 - kAgreementNearFraction) * both)
      g.mismatch = fmt::format("{} of {} shared voxels differ by more than a voxel; first {}", g.far, g.both_active,
                               first_far);
    else if (closed && double(g.sign_disagree) > kAgreementSignFraction * both)
      g.mismatch = fmt::format("{} of {} shared voxels disagree in sign on a closed mesh; first {}", g.sign_disagree,
                               g.both_active, first_sign);
    else if (double(g.both_active) < kAgreementSharedFraction * double(std::max(g.distband_active, g.openvdb_active)))
      g.mismatch = fmt::format("the active sets differ: {} shared of {} (distband) and {} (OpenVDB)", g.both_active,
                               g.distband_active, g.openvdb_active);
  }
  *out = g;
  return {};
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
  bool smoke = false;
  app.add_flag("--smoke", smoke, "tests/data's meshes at 64^3, 2 threads, one timed rep (the CTest run)");
  CLI11_PARSE(app, argc, argv);
  if (smoke) {
    if (app.get_option("--mesh-dir")->count() == 0) mesh_dir = DISTBAND_BENCH_DIR "/../tests/data/meshes";
    if (app.get_option("--meshes")->count() == 0) meshes = {"bunny.obj", "fandisk.off", "teapot.obj"};
    if (app.get_option("--resolutions")->count() == 0) resolutions = {64};
    threads = {2};
    reps = 1;
  }
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
  const std::string dist_meta = dir + "/distband.json";

  std::string md = fmt::format(
      "Whole process, exec to exit (read mesh, narrow band half-width {} voxels, write .vdb); medians of {} "
      "alternating runs; CPU = user + system of the child (all threads).\n\n"
      "| mesh | res | threads | distband s | OpenVDB s | ratio | distband CPU s | OpenVDB CPU s | CPU ratio | peak RSS "
      "MiB distband / OpenVDB | RSS ratio | distband load+seeds s | distband engine s | distband write s | distband "
      "start+exit s | active voxels distband / "
      "OpenVDB | max diff (vox) | sign diff | same job |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      half_width, reps);
  std::fputs(md.c_str(), stdout);
  std::fflush(stdout);
  json rows = json::array();
  bench::Verdict verdict("whole_process_bench");
  for (int res : resolutions)
    for (const std::string& mesh : meshes)
      for (int t : threads) {
        const std::string mesh_path = mesh_dir + "/" + mesh;
        const std::string name = fmt::format("{} {}^3, {} threads", mesh, res, t);
        const std::vector<std::string> dist_args = {distband_bin,        "compute",        "--mesh",
                                                    mesh_path,           "--resolution",   std::to_string(res),
                                                    "--limit-voxels",    std::to_string(half_width),
                                                    "--threads",         std::to_string(t), "--out", dist_out};
        // Warm-up (untimed): distband first, with --meta, so the peer gets the grid distband planned for the job.
        std::vector<std::string> meta_args = dist_args;
        meta_args.insert(meta_args.end(), {"--meta", dist_meta});
        const ChildRun w1 = runChild(meta_args, dist_log);
        PlannedGrid planned;
        std::string meta_error = w1.status == 0 ? readPlannedGrid(dist_meta, &planned) : std::string();
        if (w1.status != 0 || !meta_error.empty()) {
          verdict.fail(name, fmt::format("distband failed (exit {}) {}", w1.status, meta_error));
          continue;
        }
        auto exact = [](double v) { return fmt::format("{:.17g}", v); };
        const std::vector<std::string> peer_args = {
            peer_bin,     "--mesh",       mesh_path,
            "--voxel-size", exact(planned.voxel_size),
            "--origin",   exact(planned.origin.x) + "," + exact(planned.origin.y) + "," + exact(planned.origin.z),
            "--dims",     fmt::format("{},{},{}", planned.dims.x, planned.dims.y, planned.dims.z),
            "--half-width", exact(planned.halfWidthVoxels()),
            "--threads",  std::to_string(t), "--out", peer_out};
        const ChildRun w2 = runChild(peer_args, peer_log, peer_env);
        if (w2.status != 0) {
          verdict.fail(name, fmt::format("the OpenVDB peer failed (exit {})", w2.status));
          continue;
        }
        // The check that both did the same job (compareFiles).
        Agreement agree;
        const bool closed = [&] {
          TriangleMesh m;
          MeshReport report;
          return loadMesh(mesh_path, &m, &report).ok() && report.closed();
        }();
        if (std::string e = compareFiles(dist_out, peer_out, planned, closed, &agree); !e.empty()) {
          verdict.fail(name, e);
          continue;
        }
        if (!agree.mismatch.empty()) verdict.fail(name, agree.mismatch);
        std::vector<double> dw, dc, pw, pc, engine, write, before_engine, outside_main;
        double d_rss = 0, p_rss = 0;  // peak RSS, MiB: the largest over the timed runs
        for (int r = 0; r < reps; ++r) {
          auto runDistband = [&] {
            const ChildRun c = runChild(dist_args, dist_log);
            if (c.status != 0) verdict.fail(name, fmt::format("distband failed (exit {})", c.status));
            dw.push_back(c.wall_s);
            dc.push_back(c.cpu_s);
            d_rss = std::max(d_rss, c.max_rss_mb);
            const std::string log = readText(dist_log);
            engine.push_back(phaseSeconds(log, "engine "));
            write.push_back(phaseSeconds(log, "(write "));
            const double total = phaseSeconds(log, "total ");  // runCompute's clock: after start-up, before exit
            before_engine.push_back(total - engine.back() - write.back());
            outside_main.push_back(c.wall_s - total);
          };
          auto runPeer = [&] {
            const ChildRun c = runChild(peer_args, peer_log, peer_env);
            if (c.status != 0) verdict.fail(name, fmt::format("the OpenVDB peer failed (exit {})", c.status));
            pw.push_back(c.wall_s);
            pc.push_back(c.cpu_s);
            p_rss = std::max(p_rss, c.max_rss_mb);
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
            "| {} | {}³ | {} | {:.3f} | {:.3f} | **{:.2f}×** | {:.3f} | {:.3f} | {:.2f}× | {:.0f} / {:.0f} | {:.2f}× | "
            "{:.3f} | {:.3f} | {:.3f} | {:.3f} | {} / {} | {:.3f} | {} | {} |\n",
            mesh, res, t, dwm, pwm, dwm / pwm, dcm, pcm, dcm / pcm, d_rss, p_rss, d_rss / p_rss, median(before_engine),
            median(engine), median(write), median(outside_main), agree.distband_active, agree.openvdb_active,
            agree.max_diff_vox, agree.sign_disagree, agree.mismatch.empty() ? "yes" : "**NO**");
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
                        {"distband_peak_rss_mib", d_rss},
                        {"openvdb_peak_rss_mib", p_rss},
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
                        {"sign_disagree", agree.sign_disagree},
                        {"beyond_one_voxel", agree.far},
                        {"same_job", agree.mismatch.empty()}});
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
  if (!tag.empty()) distband::bench::writeResultFile(out_dir + "/" + tag + ".md", md);
  if (!json_path.empty()) distband::bench::writeResultFile(json_path, json({{"rows", rows}}).dump(2) + "\n");
  return verdict.finish();
}
