#include "client/remote_commands.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <thread>

#include <fmt/format.h>

#include "client/brick_sink.h"
#include "client/compute_command.h"
#include "client/field_outputs.h"
#include "client/progress.h"
#include "client/remote_client.h"
#include "client/remote_connection.h"
#include "core/io/isosurface.h"
#include "core/io/npy.h"
#include "core/io/slice_png.h"
#include "core/io/vdb_writer.h"

namespace distband {
namespace {

struct QueryArgs {
  ConnectionArgs connection;
  std::string mesh, points, volume, asset;
  int resolution = 0;
  int padding = -1;  ///< -1: the server's default
  double voxel_size = 0;
  std::string dims, origin, box;
  std::string stencil = "auto", mode = "exact", sign, encoding = "float32", progress = "auto";
  double segment = 0;
  double limit = 0;
  double limit_voxels = 0;
  double deadline_s = 0;
  OutputFlags outputs;
};

/// The client for a subcommand's connection flags, or "" and a message naming the flag.
std::unique_ptr<RemoteClient> connect(const ConnectionArgs& a, const char* command, const CliContext& ctx) {
  RemoteClientOptions options;
  if (std::string e = makeClientOptions(a, &options); !e.empty()) {
    ctx.err << "distband " << command << ": " << e << "\n";
    return nullptr;
  }
  return std::make_unique<RemoteClient>(a.server, options);
}

/// Exit code of a failed RPC: the caller's fault -> usage (2), otherwise failure (1).
int exitCodeOf(const grpc::Status& s) {
  switch (s.error_code()) {
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::OUT_OF_RANGE: return kExitUsage;
    case grpc::StatusCode::CANCELLED: return kExitInterrupted;
    default: return kExitFailure;
  }
}

// A server's answer as a sentence: what kind of problem it is, then the server's own message (which names the field).
std::string describe(const grpc::Status& s) {
  const std::string& m = s.error_message();
  switch (s.error_code()) {
    case grpc::StatusCode::INVALID_ARGUMENT: return "the server refused the request: " + m;
    case grpc::StatusCode::NOT_FOUND: return "the server does not have it: " + m;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "the server is over a limit or busy: " + m;
    case grpc::StatusCode::UNAVAILABLE: return "the server cannot be reached or is shutting down: " + m;
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "the deadline passed before the server finished: " + m;
    case grpc::StatusCode::CANCELLED: return "the call was cancelled: " + m;
    case grpc::StatusCode::UNAUTHENTICATED:
      return "the server needs a valid token (--token-file or DISTBAND_TOKEN): " + m;
    case grpc::StatusCode::PERMISSION_DENIED: return "the server refused the credentials: " + m;
    default: return fmt::format("the server failed (gRPC status {}): {}", int(s.error_code()), m);
  }
}

template <typename Enum>
using NameTable = std::initializer_list<std::pair<const char*, Enum>>;

template <typename Enum>
bool pick(const std::string& text, NameTable<Enum> table, Enum* out) {
  for (const auto& [name, value] : table)
    if (text == name) {
      *out = value;
      return true;
    }
  return false;
}

/// The flag's name of a value the header reports (the first name in the table that maps to it).
template <typename Enum>
std::string nameOf(Enum value, NameTable<Enum> table) {
  for (const auto& [name, v] : table)
    if (v == value) return name;
  return "?";
}

// The names --stencil and --sign take, read both ways (flag -> request, header -> what the CLI prints).
const NameTable<v1::Stencil> kStencilNames = {{"auto", v1::STENCIL_UNSPECIFIED}, {"cubic6", v1::STENCIL_CUBIC6},
                                              {"cubic18", v1::STENCIL_CUBIC18}, {"cubic26", v1::STENCIL_CUBIC26},
                                              {"fcc12", v1::STENCIL_FCC12}};
const NameTable<v1::SignMode> kSignNames = {
    {"auto", v1::SIGN_MODE_AUTO},       {"unsigned", v1::SIGN_MODE_UNSIGNED}, {"pseudonormal", v1::SIGN_MODE_PSEUDONORMAL},
    {"winding", v1::SIGN_MODE_WINDING}, {"parity", v1::SIGN_MODE_PARITY},     {"mask-inside", v1::SIGN_MODE_MASK_INSIDE}};

std::string closestText(v1::ClosestFeature closest) {
  switch (closest) {
    case v1::CLOSEST_FEATURE_TRIANGLE: return "triangle";
    case v1::CLOSEST_FEATURE_POINT: return "point";
    case v1::CLOSEST_FEATURE_VOXEL: return "voxel";
    default: return "";
  }
}

void setVec(v1::Vec3* v, const Vec3d& p) {
  v->set_x(p.x);
  v->set_y(p.y);
  v->set_z(p.z);
}

/// Builds the request (and uploads a mesh/volume first). Returns "" or a usage message; *status on RPC errors.
std::string buildRequest(const QueryArgs& a, RemoteClient& client, const CliContext& ctx, v1::QueryRequest* r,
                         grpc::Status* status) {
  const int sources = int(!a.mesh.empty()) + int(!a.points.empty()) + int(!a.volume.empty()) + int(!a.asset.empty());
  if (sources != 1) return "give exactly one seed source: --mesh, --points, --volume or --asset";
  if (!a.mesh.empty()) {
    v1::UploadReply up;
    *status = client.uploadMeshFile(a.mesh, &up);
    if (!status->ok()) return {};
    ctx.out << fmt::format("uploaded {}: {} ({} triangles{})\n", a.mesh, up.asset_id(), up.mesh().triangles(),
                           up.already_cached() ? ", already cached" : "");
    r->set_asset_id(up.asset_id());
  } else if (!a.volume.empty()) {
    std::vector<uint8_t> mask;
    Coord dims;
    if (Status s = readNpyMask(a.volume, &mask, &dims); !s.ok()) return s.message();
    v1::UploadReply up;
    *status = client.uploadVolume(dims, mask, a.volume, &up);
    if (!status->ok()) return {};
    ctx.out << fmt::format("uploaded {}: {}\n", a.volume, up.asset_id());
    r->set_asset_id(up.asset_id());
  } else if (!a.points.empty()) {
    std::vector<Vec3d> pts;
    if (std::string e = parsePointList(a.points, &pts); !e.empty()) return e;
    for (const Vec3d& p : pts) setVec(r->mutable_points()->add_points(), p);
  } else {
    r->set_asset_id(a.asset);
  }
  v1::GridSpec* g = r->mutable_grid();
  if (a.voxel_size != 0) g->set_voxel_size(a.voxel_size);
  if (a.resolution != 0) g->set_resolution(uint32_t(std::max(0, a.resolution)));
  if (a.padding >= 0) g->set_padding(uint32_t(a.padding));
  if (!a.dims.empty()) {
    Coord d;
    if (std::string e = parseDims(a.dims, &d); !e.empty()) return e;
    g->mutable_dims()->set_x(uint32_t(d.x));
    g->mutable_dims()->set_y(uint32_t(d.y));
    g->mutable_dims()->set_z(uint32_t(d.z));
  }
  if (!a.origin.empty()) {
    Vec3d o;
    if (std::string e = parseVec3(a.origin, "--origin", &o); !e.empty()) return e;
    setVec(g->mutable_origin(), o);
  }
  if (!a.box.empty()) {
    const size_t comma = [&] {
      size_t n = 0, i = 0;
      for (; i < a.box.size(); ++i)
        if (a.box[i] == ',' && ++n == 3) break;
      return i;
    }();
    if (comma >= a.box.size()) return "--box: expected six comma-separated numbers x0,y0,z0,x1,y1,z1";
    Vec3d lo, hi;
    if (std::string e = parseVec3(a.box.substr(0, comma), "--box (min)", &lo); !e.empty()) return e;
    if (std::string e = parseVec3(a.box.substr(comma + 1), "--box (max)", &hi); !e.empty()) return e;
    setVec(g->mutable_box()->mutable_min(), lo);
    setVec(g->mutable_box()->mutable_max(), hi);
  }
  v1::Stencil stencil;
  if (!pick(a.stencil, kStencilNames, &stencil))
    return fmt::format("--stencil '{}': expected auto, cubic6, cubic18, cubic26 or fcc12", a.stencil);
  r->set_stencil(stencil);
  v1::PropagationMode mode;
  if (!pick(a.mode, {{"exact", v1::PROPAGATION_MODE_EXACT}, {"exact-feature", v1::PROPAGATION_MODE_EXACT},
                     {"paper", v1::PROPAGATION_MODE_PAPER}}, &mode))
    return fmt::format("--mode '{}': expected exact (exact-feature) or paper", a.mode);
  r->set_mode(mode);
  if (!a.sign.empty()) {
    v1::SignMode sign;
    if (!pick(a.sign, kSignNames, &sign))
      return fmt::format("--sign '{}': expected auto, pseudonormal, winding, parity, unsigned or mask-inside", a.sign);
    r->set_sign(sign);
  }
  v1::BrickEncoding enc;
  if (!pick(a.encoding, {{"float32", v1::BRICK_ENCODING_FLOAT32}, {"float16", v1::BRICK_ENCODING_FLOAT16}}, &enc))
    return fmt::format("--encoding '{}': expected float32 or float16", a.encoding);
  r->set_encoding(enc);
  r->set_segment_length(a.segment);
  r->set_limit(a.limit);
  r->set_limit_voxels(a.limit_voxels);
  r->set_closest_feature(!a.outputs.closest.empty());
  return {};
}

int runQuery(const QueryArgs& a, const CliContext& ctx) {
  auto usage = [&](const std::string& msg) {
    ctx.err << "distband query: " << msg << "\n";
    return kExitUsage;
  };
  // Validate every flag and output path before any network traffic, naming the flag.
  if (a.limit_voxels != 0 && !(a.limit_voxels > 0 && std::isfinite(a.limit_voxels)))
    return usage(fmt::format("--limit-voxels must be finite and > 0 (got {})", a.limit_voxels));
  OutputPlan plan;
  const double limit_world = a.limit_voxels > 0 ? std::numeric_limits<double>::quiet_NaN()
                             : a.limit > 0      ? a.limit
                                                : std::numeric_limits<double>::infinity();
  if (std::string e = checkOutputFlags(a.outputs, limit_world, &plan); !e.empty()) return usage(e);
  if (!a.mesh.empty()) {  // the upload reads it only after connecting: check it is there now
    std::error_code ec;
    if (!std::filesystem::is_regular_file(a.mesh, ec))
      return usage(fmt::format("--mesh {}: no such file", a.mesh));
    if (meshFormatFromPath(a.mesh) == v1::MESH_FORMAT_UNSPECIFIED)
      return usage(fmt::format("--mesh {}: unsupported mesh format (expected .obj, .off, .ply or .stl)", a.mesh));
  }
  if (!a.volume.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(a.volume, ec)) return usage(fmt::format("--volume {}: no such file", a.volume));
  }
  ProgressMode pmode;
  if (!pick(a.progress, {{"auto", ProgressMode::kAuto}, {"plain", ProgressMode::kPlain},
                         {"quiet", ProgressMode::kQuiet}, {"terminal", ProgressMode::kTerminal}}, &pmode))
    return usage(fmt::format("--progress '{}': expected auto, plain, terminal or quiet", a.progress));

  std::unique_ptr<RemoteClient> connection = connect(a.connection, "query", ctx);
  if (!connection) return kExitUsage;
  RemoteClient& client = *connection;
  v1::QueryRequest request;
  grpc::Status status;
  if (std::string e = buildRequest(a, client, ctx, &request, &status); !e.empty()) return usage(e);
  if (!status.ok()) {
    ctx.err << "distband query: upload failed: " << describe(status) << "\n";
    return exitCodeOf(status);
  }

  FieldOutputs outputs(plan);
  std::unique_ptr<ProgressDisplay> progress;
  std::string setup_error;
  RemoteQueryCallbacks cb;
  cb.on_header = [&](const Grid& grid, const v1::QueryHeader& h) {
    ctx.out << fmt::format("query {}: grid {}x{}x{}, voxel size {:g}, origin ({:g}, {:g}, {:g}), limit {:g}, {}\n",
                           h.query_id(), grid.dims().x, grid.dims().y, grid.dims().z, grid.voxelSize(),
                           grid.origin().x, grid.origin().y, grid.origin().z, h.limit(),
                           h.signed_() ? "signed" : "unsigned");
    if (h.algorithm() == "separable")
      ctx.out << "algorithm: separable (a seed volume over the whole grid: an exact separable EDT; the first segment "
                 "arrives once the whole field is known)\n";
    const std::string sign = nameOf(h.sign(), kSignNames);
    if (h.sign() != v1::SIGN_MODE_UNSIGNED || h.sign_reason().rfind("auto", 0) == 0)
      ctx.out << fmt::format("sign: {} ({})\n", sign, h.sign_reason());
    if (h.band_clipped())
      ctx.err << "distband query: " << clippedBandWarning(int(h.padding()), h.limit() / grid.voxelSize(), a.padding >= 0)
              << "\n";
    FieldDescription field;
    field.grid = grid;
    field.limit_world = h.limit();
    field.signed_distance = h.signed_();
    field.sign_from_band = h.signed_();  // no inside labels on the client: signs come from the delivered band
    field.stencil = nameOf(h.stencil(), kStencilNames);
    field.mode = h.mode() == v1::PROPAGATION_MODE_PAPER ? "paper" : "exact";
    if (h.signed_()) field.sign = sign;
    field.sign_reason = h.sign_reason();
    field.padding_voxels = a.dims.empty() ? int(h.padding()) : -1;
    field.band_clipped = h.band_clipped();
    field.segment_length_world = h.segment_length();
    field.closest_feature = closestText(h.closest_feature());
    // The input file's name leads a slice's title (none for point lists and stored assets).
    field.title = std::filesystem::path(!a.mesh.empty() ? a.mesh : a.volume).filename().string();
    if (std::string e = outputs.open(field); !e.empty()) {
      setup_error = a.limit_voxels > 0 && e.rfind("--isosurface", 0) == 0
                        ? fmt::format("{} (--limit-voxels {:g})", e, a.limit_voxels)
                        : e;
      return false;
    }
    ProgressOptions po;
    po.mode = pmode;
    po.limit_world = h.limit();
    po.segment_length_world = h.segment_length();
    po.expected_voxels = int64_t(h.expected_voxels());
    progress = std::make_unique<ProgressDisplay>(po);
    return true;
  };
  uint64_t segment_bytes = 0;
  int64_t committed_voxels = 0;
  cb.on_bricks = [&](SegmentBricks&& batch, uint64_t bytes) {
    segment_bytes += bytes;
    int64_t voxels = 0;
    for (const Brick& b : batch.bricks) voxels += b.mask.count();
    progress->onData(int64_t(batch.bricks.size()), voxels, bytes);
    outputs.add(std::move(batch));
    return true;
  };
  cb.on_segment_done = [&](const v1::SegmentDone& d) {
    outputs.commitSegment(d.upper());
    committed_voxels += int64_t(d.voxels());
    SegmentProgress sp;
    sp.index = int(d.segment());
    sp.lower_world = d.lower();
    sp.upper_world = d.upper();
    sp.bricks = int64_t(d.bricks());
    sp.voxels = int64_t(d.voxels());
    sp.bytes = segment_bytes;
    segment_bytes = 0;
    sp.last = d.last();
    progress->onSegment(sp);
    return true;
  };

  // SIGINT/SIGTERM: cancel the query on the server (the engine stops) and write nothing.
  QueryCanceller canceller;
  std::atomic<bool> done{false};
  std::thread watcher([&] {
    while (!done.load()) {
      if (ctx.interrupted && ctx.interrupted()) {
        canceller.cancel();
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
  RemoteQueryOptions qo;
  qo.canceller = &canceller;
  qo.deadline = std::chrono::milliseconds(int64_t(a.deadline_s * 1000));
  const RemoteQueryResult result = client.query(request, cb, qo);
  done = true;
  watcher.join();

  if (!setup_error.empty()) {
    if (progress) progress->finish(false, setup_error);
    return usage(setup_error);
  }
  if (!result.status.ok()) {
    if (progress) progress->finish(false, describe(result.status));
    if (canceller.cancelled()) {
      // Ctrl-C: the server stopped; keep every complete segment received (marked incomplete), drop the rest.
      RunOutcome run;
      run.complete = false;
      run.voxels = committed_voxels;
      run.seconds = result.total_seconds;
      std::vector<std::string> wrote;
      const std::string e = result.have_header ? outputs.finish(run, &wrote) : "nothing arrived: nothing written";
      for (const std::string& line : wrote) ctx.out << line << "\n";
      ctx.err << "distband query: interrupted; " << (e.empty() ? outputs.keptSummary() : e) << "\n";
      return kExitInterrupted;
    }
    ctx.err << "distband query: " << describe(result.status) << "\n";
    return result.status.error_code() == grpc::StatusCode::CANCELLED ? kExitFailure : exitCodeOf(result.status);
  }
  progress->finish(true);
  const v1::QuerySummary& s = result.summary;
  ctx.out << "segment  range                 voxels      bricks   compute_s  sent_at_s\n";
  for (const v1::SegmentTiming& t : s.segments())
    ctx.out << fmt::format("{:>7}  {}{:<9.4g},{:>9.4g}] {:>10} {:>10} {:>10.4f} {:>10.4f}\n", t.segment(),
                           t.segment() == 0 ? "[" : "(", t.lower(), t.upper(), t.voxels(), t.bricks(),
                           t.compute_seconds(), t.sent_seconds());
  ctx.out << fmt::format(
      "{} voxels, {} bricks, {} messages, {:.1f} MB; server: seeds {:.3f}s, compute {:.3f}s, total {:.3f}s; "
      "client: first bricks after {:.3f}s, done after {:.3f}s\n",
      s.voxels(), s.bricks(), result.messages, result.wire_bytes / 1e6, s.seed_seconds(), s.compute_seconds(),
      s.total_seconds(), result.first_bricks_seconds, result.total_seconds);
  RunOutcome run;
  run.voxels = int64_t(s.voxels());
  run.seconds = s.total_seconds();
  std::vector<std::string> wrote;
  const std::string e = outputs.finish(run, &wrote);
  for (const std::string& line : wrote) ctx.out << line << "\n";
  if (!e.empty()) {
    ctx.err << "distband query: " << e << "\n";
    return kExitFailure;
  }
  return kExitOk;
}

CliCommand registerQuery(CLI::App& app, const CliContext& ctx) {
  auto args = std::make_shared<QueryArgs>();
  CLI::App* cmd = app.add_subcommand(kRemoteCommands[0].name, kRemoteCommands[0].description);
  addConnectionFlags(cmd, &args->connection);
  cmd->add_option("--mesh", args->mesh, "Seed mesh (.obj .off .ply .stl), uploaded first");
  cmd->add_option("--points", args->points, "Seed points in world coordinates: \"x,y,z;x,y,z\"");
  cmd->add_option("--volume", args->volume, "Seed mask .npy (uint8/bool, shape (Z, Y, X)), uploaded first");
  cmd->add_option("--asset", args->asset, "A previously uploaded asset id");
  cmd->add_option("--resolution", args->resolution, "Voxels along the longest side (the paper's N^3)");
  cmd->add_option("--padding", args->padding,
                  "Margin around the seeds' bounds, voxels (default: at least 3 and at least the limit)");
  cmd->add_option("--voxel-size", args->voxel_size, "Voxel size in world units");
  cmd->add_option("--dims", args->dims, "Explicit grid dims X,Y,Z (with --voxel-size; volumes: the mask's)");
  cmd->add_option("--origin", args->origin, "World position of voxel (0,0,0) with --dims: x,y,z");
  cmd->add_option("--box", args->box, "Explicit world box x0,y0,z0,x1,y1,z1");
  cmd->add_option("--stencil", args->stencil,
                  "auto (the server's default: fcc12 for meshes in exact mode, else cubic26) | cubic26 | cubic18 | "
                  "cubic6 | fcc12")
      ->capture_default_str();
  cmd->add_option("--mode", args->mode, "exact (exact-feature for meshes) | paper")->capture_default_str();
  cmd->add_option("--sign", args->sign,
                  "auto (default: pseudonormal for closed meshes, winding for open ones) | pseudonormal | winding | "
                  "parity | unsigned (meshes); unsigned (default) | mask-inside (volumes)");
  cmd->add_option("--segment", args->segment, "Segment length in world units (0: one segment)");
  CLI::Option* limit = cmd->add_option("--limit", args->limit, "Distance limit in world units (0: none)");
  cmd->add_option("--limit-voxels", args->limit_voxels, "Distance limit in voxels of the grid (instead of --limit)")
      ->excludes(limit);
  cmd->add_option("--encoding", args->encoding, "float32 | float16")->capture_default_str();
  cmd->add_option("--deadline", args->deadline_s, "Give up after this many seconds (0: never)");
  cmd->add_option("--progress", args->progress, "auto | plain | terminal | quiet")->capture_default_str();
  addOutputFlags(cmd, &args->outputs);
  return {cmd, [args, &ctx] { return runQuery(*args, ctx); }};
}

CliCommand registerUpload(CLI::App& app, const CliContext& ctx) {
  struct Args {
    ConnectionArgs connection;
    std::string mesh, volume;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(kRemoteCommands[1].name, kRemoteCommands[1].description);
  addConnectionFlags(cmd, &args->connection);
  cmd->add_option("--mesh", args->mesh, "Mesh file (.obj .off .ply .stl)");
  cmd->add_option("--volume", args->volume, "Seed mask .npy (uint8/bool, shape (Z, Y, X))");
  return {cmd, [args, &ctx] {
            if (args->mesh.empty() == args->volume.empty()) {
              ctx.err << "distband upload: give exactly one of --mesh and --volume\n";
              return kExitUsage;
            }
            std::unique_ptr<RemoteClient> connection = connect(args->connection, "upload", ctx);
            if (!connection) return kExitUsage;
            RemoteClient& client = *connection;
            v1::UploadReply up;
            grpc::Status s;
            if (!args->mesh.empty()) {
              s = client.uploadMeshFile(args->mesh, &up);
            } else {
              std::vector<uint8_t> mask;
              Coord dims;
              if (Status e = readNpyMask(args->volume, &mask, &dims); !e.ok()) {
                ctx.err << "distband upload: " << e.message() << "\n";
                return kExitUsage;
              }
              s = client.uploadVolume(dims, mask, args->volume, &up);
            }
            if (!s.ok()) {
              ctx.err << "distband upload: " << describe(s) << "\n";
              return exitCodeOf(s);
            }
            ctx.out << up.asset_id() << "\n";
            if (up.has_mesh())
              ctx.out << fmt::format("mesh: {} vertices, {} triangles, {} degenerate dropped, {} boundary edges\n",
                                     up.mesh().vertices(), up.mesh().triangles(), up.mesh().degenerate_triangles(),
                                     up.mesh().boundary_edges());
            ctx.out << fmt::format("{} bytes{}\n", up.bytes(), up.already_cached() ? " (already cached)" : "");
            return kExitOk;
          }};
}

CliCommand registerInfo(CLI::App& app, const CliContext& ctx) {
  auto args = std::make_shared<ConnectionArgs>();
  CLI::App* cmd = app.add_subcommand(kRemoteCommands[2].name, kRemoteCommands[2].description);
  addConnectionFlags(cmd, args.get());
  return {cmd, [args, &ctx] {
            std::unique_ptr<RemoteClient> connection = connect(*args, "info", ctx);
            if (!connection) return kExitUsage;
            RemoteClient& client = *connection;
            v1::ServerInfo i;
            if (grpc::Status s = client.info(&i); !s.ok()) {
              ctx.err << "distband info: " << describe(s) << "\n";
              return exitCodeOf(s);
            }
            auto join = [](const auto& list) {
              std::string s;
              for (const auto& x : list) s += (s.empty() ? "" : ", ") + x;
              return s;
            };
            ctx.out << fmt::format(
                "version            {}\ncompute threads    {}\nmax queries        {} ({} active)\n"
                "max voxels/query   {}\nmax upload bytes   {}\ncache bytes        {} ({} used)\n"
                "max message bytes  {}\nstencils           {}\nmodes              {}\nsign modes         {}\n"
                "mesh formats       {}\nencodings          {}\n",
                i.version(), i.compute_threads(), i.max_concurrent_queries(), i.active_queries(),
                i.max_voxels_per_query(), i.max_upload_bytes(), i.cache_bytes(), i.cache_used_bytes(),
                i.max_message_bytes(), join(i.stencils()), join(i.modes()), join(i.sign_modes()),
                join(i.mesh_formats()), join(i.encodings()));
            if (i.replicas() > 0)
              ctx.out << fmt::format("coordinator        {} replicas, tiles of at most {} voxels\n", i.replicas(),
                                     i.tile_voxels());
            return kExitOk;
          }};
}

CliCommand registerHealth(CLI::App& app, const CliContext& ctx) {
  struct Args {
    ConnectionArgs connection;
    std::string service;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(kRemoteCommands[3].name, kRemoteCommands[3].description);
  addConnectionFlags(cmd, &args->connection);
  cmd->add_option("--service", args->service, "Service name (\"\": the whole server)");
  return {cmd, [args, &ctx] {
            std::unique_ptr<RemoteClient> connection = connect(args->connection, "health", ctx);
            if (!connection) return kExitUsage;
            RemoteClient& client = *connection;
            bool serving = false;
            std::string name;
            if (grpc::Status s = client.health(args->service, &serving, &name); !s.ok()) {
              ctx.err << "distband health: " << describe(s) << "\n";
              return kExitFailure;
            }
            ctx.out << name << "\n";
            return serving ? kExitOk : kExitFailure;
          }};
}

}  // namespace

std::vector<CliCommand> registerRemoteCommands(CLI::App& app, const CliContext& context) {
  return {registerQuery(app, context), registerUpload(app, context), registerInfo(app, context),
          registerHealth(app, context)};
}

}  // namespace distband
