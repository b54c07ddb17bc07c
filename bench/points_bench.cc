// points_bench: distances at arbitrary points (core/points, the path of `distband at` and QueryPoints) against Open3D's
// RaycastingScene (compute_distance, compute_signed_distance; Debian python3-open3d 0.16, bench/open3d_points.py) on
// the same mesh, the same points and the same thread count, in the same run; both checked against the brute-force
// oracle (tests/support/brute_mesh: exact distance over every triangle, sign by the exact winding number).
//   points_bench [--meshes armadillo.off,armadillo.off@sub2,bunny.obj@open] [--points 1000000] [--threads 2]
//                [--repeats 3] [--check 1000] [--out-dir DIR --tag NAME] [--smoke]
// Meshes: a file of --mesh-dir; "@subN" splits every triangle in four, N times (armadillo@sub2: 832 k triangles,
// closed);
// "@open" removes the triangles whose centroid lies in the top fifth of the box (an open mesh). Points: "uniform" in
// the bounding box grown by 10 % of its size on each side, "gaussian" around area-weighted surface samples with
// sigma = 1 % of the box diagonal; rounded to float32 (Open3D's type), the same values for both.
// Per case: the median seconds of each side's query over --repeats runs (the search / scene build timed apart), the
// throughput ratio (Open3D's seconds / ours), and on the first --check points the max distance error / diagonal and
// the sign errors (where |w - 1/2| > 0.05) of both, and whether our closest points and triangle ids agree with the
// exact distance. Exit 1 when ours is off (error > 1e-6 diagonal, a sign error, a closest point or id inconsistent);
// Open3D's errors are reported, not judged. Without open3d the peer columns are empty (exit 77 with --smoke: CTest
// skips).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "bench/bench_util.h"
#include "core/io/npy.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/point_plan.h"
#include "tests/support/brute_mesh.h"

namespace distband::bench {
namespace {

namespace fs = std::filesystem;

struct Options {
  std::string mesh_dir;
  std::vector<std::string> meshes = {"armadillo.off", "armadillo.off@sub2", "bunny.obj@open"};
  int64_t points = 1000000;
  int threads = 2;
  int repeats = 3;
  int check = 1000;
  std::string out_dir, tag = "points_bench";
  bool smoke = false;
};

void bounds(const TriangleMesh& m, Vec3d* lo, Vec3d* hi) {
  *lo = *hi = m.vertices[0];
  for (const Vec3d& v : m.vertices) {
    *lo = {std::min(lo->x, v.x), std::min(lo->y, v.y), std::min(lo->z, v.z)};
    *hi = {std::max(hi->x, v.x), std::max(hi->y, v.y), std::max(hi->z, v.z)};
  }
}

/// Every triangle split in four, edge midpoints shared (a closed mesh stays closed).
TriangleMesh subdivide(const TriangleMesh& in) {
  TriangleMesh out;
  out.vertices = in.vertices;
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
  auto midpoint = [&](uint32_t a, uint32_t b) {
    const auto key = std::minmax(a, b);
    auto [it, fresh] = mid.try_emplace({key.first, key.second}, uint32_t(out.vertices.size()));
    if (fresh) out.vertices.push_back((in.vertices[a] + in.vertices[b]) * 0.5);
    return it->second;
  };
  for (const auto& t : in.triangles) {
    const uint32_t ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
    out.triangles.push_back({t[0], ab, ca});
    out.triangles.push_back({ab, t[1], bc});
    out.triangles.push_back({ca, bc, t[2]});
    out.triangles.push_back({ab, bc, ca});
  }
  return out;
}

/// Without the triangles whose centroid is in the top fifth of the box (z).
TriangleMesh openUp(const TriangleMesh& in) {
  Vec3d lo, hi;
  bounds(in, &lo, &hi);
  TriangleMesh out;
  out.vertices = in.vertices;
  for (const auto& t : in.triangles) {
    const double z = (in.vertices[t[0]].z + in.vertices[t[1]].z + in.vertices[t[2]].z) / 3;
    if (z < lo.z + 0.8 * (hi.z - lo.z)) out.triangles.push_back(t);
  }
  return out;
}

std::vector<Vec3d> samplePoints(const TriangleMesh& m, int64_t n, bool gaussian, uint32_t seed) {
  Vec3d lo, hi;
  bounds(m, &lo, &hi);
  const Vec3d size = hi - lo;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, 0.01 * size.length());
  std::vector<double> area(m.triangles.size());
  double total = 0;
  for (size_t i = 0; i < m.triangles.size(); ++i) {
    const auto& t = m.triangles[i];
    total += 0.5 * (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]).length();
    area[i] = total;
  }
  std::vector<Vec3d> p(static_cast<size_t>(n));
  for (Vec3d& q : p) {
    if (!gaussian) {
      q = {lo.x + size.x * (1.2 * u(rng) - 0.1), lo.y + size.y * (1.2 * u(rng) - 0.1),
           lo.z + size.z * (1.2 * u(rng) - 0.1)};
    } else {
      const size_t i =
          std::min(size_t(std::lower_bound(area.begin(), area.end(), u(rng) * total) - area.begin()), area.size() - 1);
      const auto& t = m.triangles[i];
      double a = u(rng), b = u(rng);
      if (a + b > 1) a = 1 - a, b = 1 - b;
      q = m.vertices[t[0]] * (1 - a - b) + m.vertices[t[1]] * a + m.vertices[t[2]] * b + Vec3d{g(rng), g(rng), g(rng)};
    }
    q = {double(float(q.x)), double(float(q.y)), double(float(q.z))};
  }
  return p;
}

struct Side {
  double build_seconds = 0, unsigned_seconds = 0, signed_seconds = 0;
  double max_error = 0;  ///< / diagonal, signed distances against the exact ones
  int64_t sign_errors = 0, sign_checked = 0;
  int64_t closest_errors = 0;  ///< ours: checked points whose closest point or triangle id disagree with the distance
  bool present = false;
  std::string version;
};

/// Our side: the search built as `distband at` builds it, queried on all points.
Status runOurs(const TriangleMesh& mesh, const MeshReport& report, const std::vector<Vec3d>& at, int repeats,
               size_t check, std::vector<double>* signed_distance, std::vector<Vec3d>* closest,
               std::vector<int64_t>* feature, Side* side) {
  FieldRequest signed_request, unsigned_request;
  signed_request.seeds = unsigned_request.seeds = SeedKind::kMesh;
  unsigned_request.mesh_sign = SignMethod::kUnsigned;
  PointPlan signed_plan, unsigned_plan;
  if (Status s = planPoints(signed_request, &report, nullptr, &signed_plan); !s.ok()) return s;
  if (Status s = planPoints(unsigned_request, &report, nullptr, &unsigned_plan); !s.ok()) return s;
  PointSeedSource source;
  source.mesh = &mesh;
  auto t0 = Clock::now();
  PointSearch signed_search;
  if (Status s = completePointSearch(signed_plan, source, nullptr, &signed_search); !s.ok()) return s;
  side->build_seconds = since(t0);
  PointSearch unsigned_search;
  unsigned_search.seeds = SeedKind::kMesh;
  unsigned_search.mesh = signed_search.mesh;  // the same BVH: only the sign differs
  if (Status s = completePointSearch(unsigned_plan, source, nullptr, &unsigned_search); !s.ok()) return s;
  std::vector<double> d(at.size());
  std::vector<double> ts, tu;
  for (int r = 0; r < repeats; ++r) {
    t0 = Clock::now();
    if (Status s = queryPoints(unsigned_search, at.data(), at.size(), unsigned_plan.queryOptions(nullptr), {d.data()});
        !s.ok())
      return s;
    tu.push_back(since(t0));
    t0 = Clock::now();
    if (Status s = queryPoints(signed_search, at.data(), at.size(), signed_plan.queryOptions(nullptr), {d.data()});
        !s.ok())
      return s;
    ts.push_back(since(t0));
  }
  side->unsigned_seconds = median(tu);
  side->signed_seconds = median(ts);
  side->present = true;
  *signed_distance = std::move(d);
  // The closest points and triangles of the first `check` points (untimed), for judgeClosest.
  std::vector<double> dc(check);
  closest->resize(check);
  feature->resize(check);
  return queryPoints(signed_search, at.data(), check, signed_plan.queryOptions(nullptr),
                     {dc.data(), closest->data(), feature->data()});
}

/// Whether each closest point and triangle id agree with the exact distance: the triangle's own distance (brute
/// force over that one triangle) and the closest point's distance are the exact distance, and the closest point lies
/// on that triangle. Counts the points where they do not.
void judgeClosest(const TriangleMesh& mesh, const std::vector<Vec3d>& at, const std::vector<double>& exact,
                  const std::vector<Vec3d>& closest, const std::vector<int64_t>& feature, double diagonal, Side* side) {
  const double tolerance = 1e-9 * diagonal;
  std::atomic<int64_t> errors{0};
  tbb::parallel_for(size_t(0), exact.size(), [&](size_t i) {
    const int64_t id = feature[i];
    if (id < 0 || uint64_t(id) >= mesh.triangles.size()) {
      ++errors;
      return;
    }
    TriangleMesh one;
    for (int k = 0; k < 3; ++k) one.vertices.push_back(mesh.vertices[mesh.triangles[size_t(id)][size_t(k)]]);
    one.triangles.push_back({0, 1, 2});
    const bool ok = std::abs(testing::bruteDistance(one, at[i]) - exact[i]) <= tolerance &&
                    std::abs((at[i] - closest[i]).length() - exact[i]) <= tolerance &&
                    testing::bruteDistance(one, closest[i]) <= tolerance;
    errors += !ok;
  });
  side->closest_errors = errors;
}

template <typename T>
std::string npy(const char* descr, const std::vector<T>& v, int64_t columns) {
  return encodeNpy(
      descr,
      columns ? std::vector<int64_t>{int64_t(v.size()) / columns, columns} : std::vector<int64_t>{int64_t(v.size())},
      v.data(), v.size() * sizeof(T));
}

/// Open3D's side (a child process): its timings, and its signed distances at the first `check` points.
void runPeer(const TriangleMesh& mesh, const std::vector<Vec3d>& at, const Options& o, const fs::path& dir,
             std::vector<float>* signed_distance, Side* side) {
  std::vector<float> v, p;
  std::vector<uint32_t> t;
  for (const Vec3d& x : mesh.vertices) v.insert(v.end(), {float(x.x), float(x.y), float(x.z)});
  for (const auto& x : mesh.triangles) t.insert(t.end(), {x[0], x[1], x[2]});
  for (const Vec3d& x : at) p.insert(p.end(), {float(x.x), float(x.y), float(x.z)});
  std::ofstream(dir / "vertices.npy", std::ios::binary) << npy("<f4", v, 3);
  std::ofstream(dir / "triangles.npy", std::ios::binary) << npy("<u4", t, 3);
  std::ofstream(dir / "points.npy", std::ios::binary) << npy("<f4", p, 3);
  const auto [out, rc] = runCommand(fmt::format("/usr/bin/python3 {}/open3d_points.py {} {} {} {}", DISTBAND_BENCH_DIR,
                                                dir.string(), o.threads, o.repeats, o.check));
  if (rc != 0) {
    std::fprintf(stderr, "open3d peer unavailable (exit %d): %s\n", rc, out.c_str());
    return;
  }
  auto number = [&out = out](const char* key) {  // clang 14 cannot capture a structured binding implicitly
    const size_t i = out.find(fmt::format("\"{}\": ", key));
    return i == std::string::npos ? NAN : std::atof(out.c_str() + i + std::strlen(key) + 4);
  };
  const size_t vi = out.find("\"version\": \"");
  if (vi != std::string::npos) side->version = out.substr(vi + 12, out.find('"', vi + 12) - vi - 12);
  side->build_seconds = number("build_seconds");
  side->unsigned_seconds = number("unsigned_seconds");
  side->signed_seconds = number("signed_seconds");
  NpyArray a;
  if (!readNpy((dir / "open3d_signed.npy").string(), &a).ok() || a.descr != "<f4") return;
  signed_distance->resize(a.data.size() / 4);
  std::memcpy(signed_distance->data(), a.data.data(), a.data.size());
  side->present = true;
}

/// Max |error| / diagonal and sign errors of `values` at the first points, against the brute-force oracle.
template <typename T>
void judge(const std::vector<double>& exact, const std::vector<double>& winding, const std::vector<T>& values,
           double diagonal, Side* side) {
  for (size_t i = 0; i < exact.size() && i < values.size(); ++i) {
    side->max_error = std::max(side->max_error, std::abs(std::abs(double(values[i])) - exact[i]) / diagonal);
    if (std::abs(winding[i] - 0.5) > 0.05 && exact[i] > 1e-9 * diagonal) {
      ++side->sign_checked;
      side->sign_errors += (double(values[i]) < 0) != (winding[i] > 0.5);
    }
  }
}

int run(const Options& o) {
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, size_t(o.threads));
  const fs::path dir = fs::temp_directory_path() / fmt::format("distband_points_bench_{}", ::getpid());
  fs::create_directories(dir);
  std::vector<std::string> rows, json;
  bool failed = false, peer_missing = false;
  for (const std::string& name : o.meshes) {
    const std::string file = name.substr(0, name.find('@'));
    const std::string variant = name.find('@') == std::string::npos ? "" : name.substr(name.find('@') + 1);
    TriangleMesh mesh;
    MeshReport report;
    if (Status s = loadMesh(o.mesh_dir + "/" + file, &mesh, &report); !s.ok()) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return 2;
    }
    if (variant.rfind("sub", 0) == 0 || variant == "open") {
      if (variant == "open") mesh = openUp(mesh);
      for (int i = 0, n = variant == "sub" ? 1 : std::atoi(variant.c_str() + 3); i < n && variant != "open"; ++i)
        mesh = subdivide(mesh);
      if (Status s = validateMesh(&mesh, &report); !s.ok()) {
        std::fprintf(stderr, "%s: %s\n", name.c_str(), s.toString().c_str());
        return 2;
      }
    }
    Vec3d lo, hi;
    bounds(mesh, &lo, &hi);
    const double diagonal = (hi - lo).length();
    for (const bool gaussian : {false, true}) {
      const char* dist = gaussian ? "gaussian" : "uniform";
      const std::vector<Vec3d> at = samplePoints(mesh, o.points, gaussian, 1234);
      std::vector<double> ours_d;
      std::vector<Vec3d> ours_closest;
      std::vector<int64_t> ours_feature;
      Side ours, peer;
      const size_t k = std::min<size_t>(size_t(o.check), at.size());
      if (Status s = runOurs(mesh, report, at, o.repeats, k, &ours_d, &ours_closest, &ours_feature, &ours); !s.ok()) {
        std::fprintf(stderr, "FAIL %s %s: %s\n", name.c_str(), dist, s.toString().c_str());
        return 1;
      }
      std::vector<float> peer_d;
      runPeer(mesh, at, o, dir, &peer_d, &peer);
      peer_missing |= !peer.present;
      std::vector<double> exact(k), winding(k);
      tbb::parallel_for(size_t(0), k, [&](size_t i) {
        exact[i] = testing::bruteDistance(mesh, at[i]);
        winding[i] = testing::bruteWinding(mesh, at[i]);
      });
      judge(exact, winding, ours_d, diagonal, &ours);
      if (peer.present) judge(exact, winding, peer_d, diagonal, &peer);
      judgeClosest(mesh, at, exact, ours_closest, ours_feature, diagonal, &ours);
      const bool ok = ours.max_error <= 1e-6 && ours.sign_errors == 0 && ours.closest_errors == 0;
      std::printf(
          "%s %s: %zu points checked against brute force: max error %.3g diagonal, %lld sign errors of %lld "
          "decided, %lld closest points or triangle ids inconsistent with the distance\n",
          name.c_str(), dist, k, ours.max_error, (long long)ours.sign_errors, (long long)ours.sign_checked,
          (long long)ours.closest_errors);
      if (!ok) {
        failed = true;
        std::fprintf(stderr, "FAIL %s %s: max error %.3g diagonal, %lld sign errors of %lld, %lld closest errors\n",
                     name.c_str(), dist, ours.max_error, (long long)ours.sign_errors, (long long)ours.sign_checked,
                     (long long)ours.closest_errors);
      }
      const double n = double(at.size());
      const double ratio_s = peer.present ? peer.signed_seconds / ours.signed_seconds : NAN;
      const double ratio_u = peer.present ? peer.unsigned_seconds / ours.unsigned_seconds : NAN;
      rows.push_back(fmt::format(
          "| {} | {} | {} | {} | {:.3f} / {:.3f} | {:.2f} / {:.2f} | {:.2f} / {:.2f} | **{:.2f}x** / {:.2f}x | "
          "{:.1e} / {:.1e} | {} / {} of {} |",
          name, mesh.triangles.size(), dist, at.size(), ours.build_seconds, peer.build_seconds,
          n / ours.signed_seconds / 1e6, peer.present ? n / peer.signed_seconds / 1e6 : NAN,
          n / ours.unsigned_seconds / 1e6, peer.present ? n / peer.unsigned_seconds / 1e6 : NAN, ratio_s, ratio_u,
          ours.max_error, peer.max_error, ours.sign_errors, peer.present ? std::to_string(peer.sign_errors) : "-",
          ours.sign_checked));
      json.push_back(fmt::format(
          "{{\"mesh\": \"{}\", \"triangles\": {}, \"points\": \"{}\", \"n\": {}, \"threads\": {}, \"repeats\": {}, "
          "\"ours\": {{\"build_s\": {}, \"signed_s\": {}, \"unsigned_s\": {}, \"max_err_diag\": {}, "
          "\"sign_errors\": {}, \"sign_checked\": {}, \"closest_errors\": {}}}, \"open3d\": {{\"present\": {}, "
          "\"version\": \"{}\", "
          "\"build_s\": {}, \"signed_s\": {}, \"unsigned_s\": {}, \"max_err_diag\": {}, \"sign_errors\": {}}}, "
          "\"ratio_signed\": {}, \"ratio_unsigned\": {}, \"ok\": {}}}",
          name, mesh.triangles.size(), dist, at.size(), o.threads, o.repeats, ours.build_seconds, ours.signed_seconds,
          ours.unsigned_seconds, ours.max_error, ours.sign_errors, ours.sign_checked, ours.closest_errors, peer.present,
          peer.version, peer.present ? peer.build_seconds : 0, peer.present ? peer.signed_seconds : 0,
          peer.present ? peer.unsigned_seconds : 0, peer.max_error, peer.sign_errors,
          std::isfinite(ratio_s) ? ratio_s : 0, std::isfinite(ratio_u) ? ratio_u : 0, ok));
      std::printf("%s\n", json.back().c_str());
      std::fflush(stdout);
    }
  }
  fs::remove_all(dir);
  std::string md = fmt::format(
      "# points_bench: distances at points, distband vs Open3D RaycastingScene\n\n"
      "{} threads, median of {} repeats, accuracy on the first {} points of each case (brute force: exact distance, "
      "sign by the exact winding number where |w - 1/2| > 0.05).\n\n"
      "| mesh | triangles | points | N | build s (ours / Open3D) | signed M pts/s (ours / Open3D) | unsigned M pts/s "
      "(ours / Open3D) | ratio signed / unsigned (Open3D s / ours s) | max err / diag (ours / Open3D) | sign errors "
      "(ours / Open3D) |\n|---|---|---|---|---|---|---|---|---|---|\n",
      o.threads, o.repeats, o.check);
  for (const std::string& r : rows) md += r + "\n";
  if (!o.out_dir.empty()) {
    std::string json_lines;
    for (const std::string& line : json) json_lines += line + "\n";
    distband::bench::writeResultFile((fs::path(o.out_dir) / (o.tag + ".md")).string(), md);
    distband::bench::writeResultFile((fs::path(o.out_dir) / (o.tag + ".json")).string(), json_lines);
  }
  std::printf("%s", md.c_str());
  if (failed) return 1;
  if (peer_missing && o.smoke) return 77;
  return 0;
}

}  // namespace
}  // namespace distband::bench

int main(int argc, char** argv) {
  distband::bench::Options o;
  o.mesh_dir = "/work/shared/data/meshes";
  CLI::App app{"distances at points: distband vs Open3D RaycastingScene"};
  app.add_option("--mesh-dir", o.mesh_dir, "directory holding the meshes");
  app.add_option("--meshes", o.meshes, "meshes (file[@subN|@open])")->delimiter(',');
  app.add_option("--points", o.points, "query points per case");
  app.add_option("--threads", o.threads, "threads, both sides");
  app.add_option("--repeats", o.repeats, "timed runs per side (median)");
  app.add_option("--check", o.check, "points checked against brute force");
  app.add_option("--out-dir", o.out_dir, "where TAG.md and TAG.json go");
  app.add_option("--tag", o.tag, "result file name");
  app.add_flag("--smoke", o.smoke, "bunny and its open variant, 20000 points, 1 repeat (exit 77 without open3d)");
  CLI11_PARSE(app, argc, argv);
  if (o.smoke) {
    if (app.get_option("--mesh-dir")->count() == 0) o.mesh_dir = DISTBAND_BENCH_DIR "/../tests/data/meshes";
    o.meshes = {"bunny.obj", "bunny.obj@open"};
    o.points = 20000;
    o.repeats = 1;
    o.check = 300;
  }
  if (o.points < 1 || o.threads < 1 || o.repeats < 1 || o.check < 0) {
    std::fprintf(stderr, "--points, --threads and --repeats must be >= 1, --check >= 0\n");
    return 2;
  }
  return distband::bench::run(o);
}
