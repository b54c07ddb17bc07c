#include "client/remote_commands.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "client/field_flags.h"
#include "client/field_outputs.h"
#include "client/interrupt_watch.h"
#include "client/progress.h"
#include "client/remote_client.h"
#include "client/remote_connection.h"
#include "core/band/band_engine.h"
#include "core/field/field_plan.h"
#include "core/io/npy.h"
#include "core/io/volume_file.h"
#include "core/seeds/mesh_seeds.h"
#include "core/stencil.h"
#include "core/seeds/mesh_sign.h"

namespace distband {
namespace {

struct QueryArgs {
  ConnectionArgs connection;
  FieldFlags field;  ///< the field flags, shared with compute (client/field_flags.h)
  std::string encoding = "float32", progress = "auto";
  OutputFlags outputs;
};

/// The client for a subcommand's connection flags, or null after a message naming the flag.
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

// distband.v1 names each enum value after its type and then the value's name as core and the flags spell it, both in
// upper snake case (STENCIL_FCC12 is "fcc12", SIGN_MODE_MASK_INSIDE "mask-inside", BRICK_ENCODING_FLOAT16
// "float16"): that one rule maps the protocol's values to names, so the client keeps no table of either.
template <typename Enum>
std::string valuePrefix() {
  std::string prefix;
  for (char c : google::protobuf::GetEnumDescriptor<Enum>()->name()) {
    if (std::isupper(static_cast<unsigned char>(c)) && !prefix.empty()) prefix += '_';
    prefix += char(std::toupper(static_cast<unsigned char>(c)));
  }
  return prefix + "_";
}

/// The protocol's value of a name; false for an unknown name (or the UNSPECIFIED value, which names nothing).
template <typename Enum>
bool protoValue(std::string_view name, Enum* out) {
  std::string full = valuePrefix<Enum>();
  for (char c : name) full += c == '-' ? '_' : char(std::toupper(static_cast<unsigned char>(c)));
  const auto* value = google::protobuf::GetEnumDescriptor<Enum>()->FindValueByName(full);
  if (!value || value->number() == 0) return false;
  *out = Enum(value->number());
  return true;
}

/// The name of a protocol value ("" for UNSPECIFIED or an unknown number).
template <typename Enum>
std::string valueName(Enum value) {
  const auto* v = google::protobuf::GetEnumDescriptor<Enum>()->FindValueByNumber(int(value));
  if (!v || v->number() == 0) return {};
  std::string name(v->name());
  name.erase(0, valuePrefix<Enum>().size());
  for (char& c : name) c = c == '_' ? '-' : char(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

/// Every named value of a protocol enum, "a or b".
template <typename Enum>
std::string valueNames() {
  const auto* descriptor = google::protobuf::GetEnumDescriptor<Enum>();
  std::string names;
  for (int i = 0; i < descriptor->value_count(); ++i) {
    const std::string name = valueName(Enum(descriptor->value(i)->number()));
    if (!name.empty()) names += (names.empty() ? "" : i + 1 == descriptor->value_count() ? " or " : ", ") + name;
  }
  return names;
}

void setVec(v1::Vec3* v, const Vec3d& p) {
  v->set_x(p.x);
  v->set_y(p.y);
  v->set_z(p.z);
}

/// The flags, checked: what to compute, how to receive it and where to write it.
struct QuerySetup {
  FieldSpec spec;
  OutputPlan outputs;
  ProgressMode progress = ProgressMode::kAuto;
  v1::BrickEncoding encoding = v1::BRICK_ENCODING_UNSPECIFIED;
  VolumeGeometry geometry;  ///< a volume file's header (uploadSeeds), with --spacing and --origin over it
};

/// Step 1: every flag and output path, before any network traffic.
std::string checkQueryFlags(const QueryArgs& a, QuerySetup* q) {
  if (std::string e = parseFieldFlags(a.field, &q->spec); !e.empty()) return e;
  FieldSpec& spec = q->spec;
  if (spec.request.second_ring)
    return "--second-ring: the service's QueryRequest has no field for the second-ring correction (distband compute "
           "--second-ring runs it)";
  spec.request.closest_features = !a.outputs.closest.empty();
  spec.request.nearest_label = !a.outputs.nearest_label.empty();
  if (std::string e = checkOutputFlags(a.outputs, spec.outputLimit(), &q->outputs); !e.empty()) return e;
  std::error_code ec;
  if (!spec.asset && !spec.source.empty() && !std::filesystem::is_regular_file(spec.source, ec))
    return fmt::format("{} {}: no such file",
                       spec.seeds == SeedKind::kMesh     ? "--mesh"
                       : spec.seeds == SeedKind::kVolume ? "--volume"
                                                         : "--points-file",
                       spec.source);
  if (!spec.asset && spec.seeds == SeedKind::kMesh && meshFormatFromPath(spec.source) == v1::MESH_FORMAT_UNSPECIFIED)
    return fmt::format("--mesh {}: unsupported mesh format (expected .obj, .off, .ply or .stl)", spec.source);
  if (!protoValue(a.encoding, &q->encoding))
    return fmt::format("--encoding '{}': expected {}", a.encoding, valueNames<v1::BrickEncoding>());
  const std::pair<const char*, ProgressMode> modes[] = {{"auto", ProgressMode::kAuto},
                                                        {"plain", ProgressMode::kPlain},
                                                        {"terminal", ProgressMode::kTerminal},
                                                        {"quiet", ProgressMode::kQuiet}};
  const auto* mode =
      std::find_if(std::begin(modes), std::end(modes), [&](const auto& m) { return a.progress == m.first; });
  if (mode == std::end(modes))
    return fmt::format("--progress '{}': expected auto, plain, terminal or quiet", a.progress);
  q->progress = mode->second;
  return {};
}

/// Step 2: uploads a mesh or volume (the request names it by its id) or names the asset. Returns "" or a usage
/// message; *status on RPC errors.
std::string uploadSeeds(QuerySetup& q, RemoteClient& client, const CliContext& ctx, v1::QueryRequest* r,
                        grpc::Status* status) {
  const FieldSpec& spec = q.spec;
  // A volume's grid: the file's header (read here, on the client) under the flags; core's defaults without either.
  q.geometry = overrideGeometry({}, spec.grid.spacing, spec.grid.origin_given);
  if (spec.seeds == SeedKind::kPoints) return {};
  if (spec.asset) {
    r->set_asset_id(spec.source);
    return {};
  }
  v1::UploadReply up;
  if (spec.seeds == SeedKind::kMesh) {
    *status = client.uploadMeshFile(spec.source, &up);
    if (!status->ok()) return {};
    ctx.out << fmt::format("uploaded {}: {} ({} triangles{})\n", spec.source, up.asset_id(), up.mesh().triangles(),
                           up.already_cached() ? ", already cached" : "");
  } else {
    VolumeImage image;
    if (Status s = readVolumeFile(spec.source, {}, &image); !s.ok()) return s.message();
    const LabelVolume& volume = image.volume;
    if (std::string e = checkMaskDims(spec, volume.dims()); !e.empty()) return e;
    q.geometry = overrideGeometry(image.geometry, spec.grid.spacing, spec.grid.origin_given);
    *status = client.uploadVolume(volume, spec.source, &up);
    if (!status->ok()) return {};
    ctx.out << fmt::format("uploaded {}: {}\n", spec.source, up.asset_id());
  }
  r->set_asset_id(up.asset_id());
  return {};
}

/// Step 3: the request's points, grid and field, as the spec asks (what it leaves unset stays unset: the server's
/// planner decides it, as compute's does).
std::string fillRequest(const QuerySetup& q, v1::QueryRequest* r) {
  const FieldSpec& spec = q.spec;
  for (const Vec3d& p : spec.points) setVec(r->mutable_points()->add_points(), p);
  const GridChoice& c = spec.grid;
  v1::GridSpec* g = r->mutable_grid();
  // An explicit lattice's spacing: a volume's geometry (file, flags, defaults), or --spacing with --dims.
  const std::optional<Vec3d> spacing = spec.seeds == SeedKind::kVolume && c.lattice ? q.geometry.spacing : c.spacing;
  const bool anisotropic = spacing && !(spacing->x == spacing->y && spacing->y == spacing->z);
  if (anisotropic)
    setVec(g->mutable_spacing(), *spacing);
  else if (spacing)
    g->set_voxel_size(spacing->x);
  else if (c.voxel_size > 0)
    g->set_voxel_size(c.voxel_size);
  if (c.resolution > 0) g->set_resolution(uint32_t(c.resolution));
  if (c.padding) g->set_padding(uint32_t(*c.padding));
  if (c.dims) {
    g->mutable_dims()->set_x(uint32_t(c.dims->x));
    g->mutable_dims()->set_y(uint32_t(c.dims->y));
    g->mutable_dims()->set_z(uint32_t(c.dims->z));
  }
  if (c.lattice) setVec(g->mutable_origin(), spec.seeds == SeedKind::kVolume ? q.geometry.origin : c.origin);
  if (c.box_min) {
    setVec(g->mutable_box()->mutable_min(), *c.box_min);
    setVec(g->mutable_box()->mutable_max(), *c.box_max);
  }
  const FieldRequest& f = spec.request;
  v1::Stencil stencil = v1::STENCIL_UNSPECIFIED;
  v1::PropagationMode mode = v1::PROPAGATION_MODE_UNSPECIFIED;
  v1::SignMode sign = v1::SIGN_MODE_UNSPECIFIED;
  const std::string_view sign_name = f.inside_negative ? kMaskInsideSign
                                     : f.mesh_sign     ? signMethodName(*f.mesh_sign)
                                                       : std::string_view();
  if ((f.stencil && !protoValue(stencilName(*f.stencil), &stencil)) ||
      (f.mode && !protoValue(modeName(*f.mode), &mode)) || (!sign_name.empty() && !protoValue(sign_name, &sign)))
    return "the protocol has no value for a choice the flags made (the service's enums and core's names disagree)";
  if (f.algorithm)
    r->set_algorithm(*f.algorithm == FieldAlgorithm::kSeparable ? v1::ALGORITHM_SEPARABLE : v1::ALGORITHM_BAND);
  r->set_stencil(stencil);
  r->set_mode(mode);
  r->set_sign(sign);
  r->set_encoding(q.encoding);
  r->set_segment_length(f.segment_length_world);
  r->set_limit(std::isfinite(f.limit_world) ? f.limit_world : 0);  // 0: none
  r->set_limit_voxels(f.limit_voxels);
  r->set_closest_feature(f.closest_features);
  r->set_labels(f.labels);
  r->set_black_border(f.black_border);
  r->set_nearest_label(f.nearest_label);
  return {};
}

/// The plan a stream's header describes (the server's planner made it), rebuilt with core's names of its values.
/// Returns "" or what in the header core does not know.
std::string planOfHeader(const v1::QueryHeader& h, SeedKind seeds, FieldPlan* plan) {
  FieldPlan p;
  p.seeds = seeds;
  const std::optional<FieldAlgorithm> algorithm = parseAlgorithm(h.algorithm());
  const std::optional<StencilKind> stencil = parseStencil(valueName(h.stencil()));
  FieldRequest sign;
  sign.seeds = seeds;
  if (!algorithm) return fmt::format("algorithm '{}'", h.algorithm());
  if (!stencil) return fmt::format("stencil {}", int(h.stencil()));
  if (!parseMode(valueName(h.mode()), &p.mode)) return fmt::format("mode {}", int(h.mode()));
  if (!requestSign(valueName(h.sign()), &sign).ok()) return fmt::format("sign {}", int(h.sign()));
  p.algorithm = *algorithm;
  p.stencil = *stencil;
  p.mesh_sign = sign.mesh_sign.value_or(SignMethod::kUnsigned);
  p.inside_negative = sign.inside_negative;
  p.sign_reason = h.sign_reason();
  p.limit_world = h.limit();
  p.segment_length_world = h.segment_length();
  p.nearest_label = h.closest_feature() == v1::CLOSEST_FEATURE_LABEL;
  p.closest_features = h.closest_feature() != v1::CLOSEST_FEATURE_NONE && !p.nearest_label;
  p.labels = h.labels();
  p.black_border = h.black_border();
  *plan = std::move(p);
  return {};
}

/// Steps 4 and 5: what arrives on the stream: the header opens the outputs and the progress display, bricks fill
/// them, each segment's marker commits it.
class QueryReceiver {
 public:
  QueryReceiver(const QuerySetup& q, const QueryArgs& a, const CliContext& ctx)
      : outputs(q.outputs),
        spec_(q.spec),
        geometry_(q.geometry),
        progress_mode_(q.progress),
        limit_voxels_flag_(a.field.limit_voxels),
        ctx_(ctx) {}

  RemoteQueryCallbacks callbacks() {
    RemoteQueryCallbacks cb;
    cb.on_header = [this](const Grid& grid, const v1::QueryHeader& h) { return onHeader(grid, h); };
    cb.on_bricks = [this](SegmentBricks&& batch, uint64_t bytes) {
      segment_bytes_ += bytes;
      int64_t voxels = 0;
      for (const Brick& b : batch.bricks) voxels += b.mask.count();
      progress->onData(int64_t(batch.bricks.size()), voxels, bytes);
      outputs.add(std::move(batch));
      return true;
    };
    cb.on_segment_done = [this](const v1::SegmentDone& d) {
      outputs.commitSegment(d.upper());
      committed_voxels += int64_t(d.voxels());
      SegmentProgress sp;
      sp.index = int(d.segment());
      sp.lower_world = d.lower();
      sp.upper_world = d.upper();
      sp.bricks = int64_t(d.bricks());
      sp.voxels = int64_t(d.voxels());
      sp.bytes = segment_bytes_;
      segment_bytes_ = 0;
      sp.last = d.last();
      progress->onSegment(sp);
      return true;
    };
    return cb;
  }

  FieldOutputs outputs;
  std::unique_ptr<ProgressDisplay> progress;
  std::string setup_error;       ///< why on_header stopped the stream
  int setup_code = kExitOk;      ///< and its exit code
  int64_t committed_voxels = 0;  ///< voxels of the complete segments (what an interrupted query keeps)

 private:
  bool onHeader(const Grid& grid, const v1::QueryHeader& h) {
    ctx_.out << fmt::format("query {}: grid {}x{}x{}, voxel size {:g}, origin ({:g}, {:g}, {:g}), limit {:g}, {}\n",
                            h.query_id(), grid.dims().x, grid.dims().y, grid.dims().z, grid.voxelSize(),
                            grid.origin().x, grid.origin().y, grid.origin().z, h.limit(),
                            h.signed_() ? "signed" : "unsigned");
    FieldPlan plan;
    if (std::string e = planOfHeader(h, spec_.seeds, &plan); !e.empty()) {
      setup_error = "the server's header names a value this client does not know: " + e;
      setup_code = kExitFailure;
      return false;
    }
    ctx_.out << algorithmLine(plan) << "\n";
    if (plan.signedField() || h.sign_reason().rfind("auto", 0) == 0)
      ctx_.out << fmt::format("sign: {} ({})\n", plan.signName(), plan.sign_reason);
    const GridPadding padding{spec_.grid.lattice ? -1 : int(h.padding()), h.band_clipped()};
    if (padding.band_clipped)
      ctx_.err << "distband query: "
               << clippedBandWarning(padding.voxels, plan.limitVoxels(grid), spec_.grid.padding.has_value()) << "\n";
    // The input file's name leads a slice's title (none for point lists and stored assets).
    const std::string title = spec_.asset ? "" : std::filesystem::path(spec_.source).filename().string();
    FieldDescription description = describeField(plan, grid, padding, title);
    if (geometry_.from_header) description.affine = volumeAffine(geometry_);
    if (std::string e = outputs.open(description); !e.empty()) {
      setup_error = limit_voxels_flag_ && e.rfind("--isosurface", 0) == 0
                        ? fmt::format("{} (--limit-voxels {:g})", e, *limit_voxels_flag_)
                        : e;
      setup_code = kExitUsage;
      return false;
    }
    ProgressOptions po;
    po.mode = progress_mode_;
    po.limit_world = h.limit();
    po.segment_length_world = h.segment_length();
    po.expected_voxels = int64_t(h.expected_voxels());
    progress = std::make_unique<ProgressDisplay>(po);
    return true;
  }

  const FieldSpec& spec_;
  VolumeGeometry geometry_;
  ProgressMode progress_mode_;
  std::optional<double> limit_voxels_flag_;
  const CliContext& ctx_;
  uint64_t segment_bytes_ = 0;
};

/// Step 6: the files and the summary, or how the stream ended early.
int finishQuery(const RemoteQueryResult& result, QueryReceiver& rx, const InterruptWatch& watch,
                const QueryCanceller& canceller, const CliContext& ctx) {
  if (!rx.setup_error.empty()) {
    if (rx.progress) rx.progress->finish(false, rx.setup_error);
    ctx.err << "distband query: " << rx.setup_error << "\n";
    return rx.setup_code;
  }
  if (!result.status.ok()) {
    if (rx.progress) rx.progress->finish(false, describe(result.status));
    const bool deadline = watch.deadlinePassed() || result.status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
    if (deadline || canceller.cancelled()) {
      // The server stopped; keep every complete segment received (marked incomplete), drop the rest.
      RunOutcome run{false, rx.committed_voxels, result.total_seconds, {}};
      return finishStoppedRun(rx.outputs, run, deadline ? RunStop::kDeadline : RunStop::kInterrupted, "query", ctx);
    }
    ctx.err << "distband query: " << describe(result.status) << "\n";
    return result.status.error_code() == grpc::StatusCode::CANCELLED ? kExitFailure : exitCodeOf(result.status);
  }
  rx.progress->finish(true);
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
  RunOutcome run{true, int64_t(s.voxels()), s.total_seconds(), {}};
  const v1::SignShares& sh = s.sign_shares();
  run.sign_shares = {int64_t(sh.pseudonormal()), int64_t(sh.winding_certified()), int64_t(sh.winding_per_voxel()),
                     int64_t(sh.parity())};
  if (run.sign_shares.total() > 0) ctx.out << "sign: " << describeSignShares(run.sign_shares) << "\n";
  std::vector<std::string> wrote;
  const std::string e = rx.outputs.finish(run, &wrote);
  for (const std::string& line : wrote) ctx.out << line << "\n";
  if (!e.empty()) {
    ctx.err << "distband query: " << e << "\n";
    return kExitFailure;
  }
  return kExitOk;
}

int runQuery(const QueryArgs& a, const CliContext& ctx) {
  const auto t_start = std::chrono::steady_clock::now();
  auto usage = [&](const std::string& msg) {
    ctx.err << "distband query: " << msg << "\n";
    return kExitUsage;
  };
  QuerySetup q;
  if (std::string e = checkQueryFlags(a, &q); !e.empty()) return usage(e);
  if (Status s = loadSeedPoints(&q.spec, nullptr); !s.ok()) return usage(s.message());
  const std::unique_ptr<RemoteClient> connection = connect(a.connection, "query", ctx);
  if (!connection) return kExitUsage;
  // Ctrl-C and --deadline trip the watch, which cancels the query on the server (its engine stops).
  QueryCanceller canceller;
  const auto deadline = q.spec.deadline(t_start);
  InterruptWatch watch(ctx.interrupted, deadline, [&canceller] { canceller.cancel(); });

  v1::QueryRequest request;
  grpc::Status status;
  if (std::string e = uploadSeeds(q, *connection, ctx, &request, &status); !e.empty()) return usage(e);
  if (!status.ok()) {
    ctx.err << "distband query: upload failed: " << describe(status) << "\n";
    return exitCodeOf(status);
  }
  if (std::string e = fillRequest(q, &request); !e.empty()) {
    ctx.err << "distband query: " << e << "\n";
    return kExitFailure;
  }
  QueryReceiver receiver(q, a, ctx);
  RemoteQueryOptions qo;
  qo.canceller = &canceller;
  if (deadline)  // the server stops at the same time, whether or not the client is still there to cancel
    qo.deadline = std::max(std::chrono::milliseconds(1),
                           std::chrono::ceil<std::chrono::milliseconds>(*deadline - std::chrono::steady_clock::now()));
  const RemoteQueryResult result = connection->query(request, receiver.callbacks(), qo);
  return finishQuery(result, receiver, watch, canceller, ctx);
}

CliCommand registerQuery(CLI::App& app, const CliContext& ctx) {
  auto args = std::make_shared<QueryArgs>();
  CLI::App* cmd = app.add_subcommand(kRemoteCommands[0].name, kRemoteCommands[0].description);
  addFieldFlags(cmd, &args->field, AssetSeeds::kYes);
  addConnectionFlags(cmd, &args->connection);
  cmd->add_option("--encoding", args->encoding, "Brick values on the wire: " + valueNames<v1::BrickEncoding>())
      ->capture_default_str();
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
  cmd->add_option("--volume", args->volume,
                  "Seed or label volume: .npy (bool/uint8/16/32, shape (Z, Y, X)), NIfTI (.nii, .nii.gz) or NRRD "
                  "(.nrrd, .nhdr); its voxels only (query --asset takes the spacing and origin)");
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
              VolumeImage image;
              if (Status e = readVolumeFile(args->volume, {}, &image); !e.ok()) {
                ctx.err << "distband upload: " << e.message() << "\n";
                return kExitUsage;
              }
              s = client.uploadVolume(image.volume, args->volume, &up);
              // An asset is its voxels: the file's geometry travels with each query.
              const VolumeGeometry& g = image.geometry;
              if (s.ok() && g.from_header)
                ctx.err << fmt::format(
                    "distband upload: the header's spacing and origin are not stored with the "
                    "asset: give query --asset {} --spacing {},{},{} --origin {},{},{}\n",
                    up.asset_id(), g.spacing.x, g.spacing.y, g.spacing.z, g.origin.x, g.origin.y, g.origin.z);
            }
            if (!s.ok()) {
              ctx.err << "distband upload: " << describe(s) << "\n";
              return exitCodeOf(s);
            }
            ctx.out << up.asset_id() << "\n";
            if (up.has_mesh())
              ctx.out << fmt::format(
                  "mesh: {} vertices, {} triangles, {} degenerate dropped, {} boundary edges{}\n", up.mesh().vertices(),
                  up.mesh().triangles(), up.mesh().degenerate_triangles(), up.mesh().boundary_edges(),
                  up.mesh().reoriented_faces() ? fmt::format(", {} faces re-oriented", up.mesh().reoriented_faces())
                                               : "");
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

namespace {

int runRemoteAt(const AtArgs& a, const ConnectionArgs& connection_args, const CliContext& ctx) {
  const auto t_start = std::chrono::steady_clock::now();
  auto usage = [&](const std::string& msg) {
    ctx.err << "distband at: " << msg << "\n";
    return kExitUsage;
  };
  AtSetup setup;
  if (std::string e = checkAtFlags(a, true, &setup); !e.empty()) return usage(e);
  FieldSpec& spec = setup.spec;
  std::error_code ec;
  if (!spec.asset && !spec.source.empty() && spec.seeds != SeedKind::kPoints &&
      !std::filesystem::is_regular_file(spec.source, ec))
    return usage(
        fmt::format("{} {}: no such file", spec.seeds == SeedKind::kMesh ? "--mesh" : "--volume", spec.source));
  if (Status s = loadSeedPoints(&spec, nullptr); !s.ok()) return usage(s.message());
  const std::unique_ptr<RemoteClient> connection = connect(connection_args, "at", ctx);
  if (!connection) return kExitUsage;
  QueryCanceller canceller;
  const auto deadline = spec.deadline(t_start);
  InterruptWatch watch(ctx.interrupted, deadline, [&canceller] { canceller.cancel(); });

  // The header: the seeds (meshes and volumes uploaded first, as query does), the sign and limit the flags gave
  // (unset: the server's planner decides), the outputs, and the query points' type.
  v1::QueryRequest uploaded;
  grpc::Status status;
  QuerySetup upload;  // uploadSeeds reads a volume file's header too; the point search takes its cubic lattice
  upload.spec = spec;
  if (std::string e = uploadSeeds(upload, *connection, ctx, &uploaded, &status); !e.empty()) return usage(e);
  if (!status.ok()) {
    ctx.err << "distband at: upload failed: " << describe(status) << "\n";
    return exitCodeOf(status);
  }
  v1::PointsHeader header;
  if (spec.seeds == SeedKind::kPoints) {
    for (const Vec3d& p : spec.points) setVec(header.mutable_points()->add_points(), p);
  } else {
    header.set_asset_id(uploaded.asset_id());
  }
  if (spec.seeds == SeedKind::kVolume && !spec.asset) {
    // The uploaded file's lattice (its header under the flags), as the in-process run takes it.
    double h = 0;
    if (std::string e = cubicVolumeLattice(upload.geometry, spec.source, &h); !e.empty()) return usage(e);
    setVec(header.mutable_volume_origin(), upload.geometry.origin);
    header.set_volume_voxel_size(h);
  }
  const FieldRequest& f = spec.request;
  v1::SignMode sign = v1::SIGN_MODE_UNSPECIFIED;
  const std::string_view sign_name = f.inside_negative ? kMaskInsideSign
                                     : f.mesh_sign     ? signMethodName(*f.mesh_sign)
                                                       : std::string_view();
  if (!sign_name.empty() && !protoValue(sign_name, &sign))
    return usage("the protocol has no value for the --sign given (the service's enums and core's names disagree)");
  header.set_sign(sign);
  header.set_limit(std::isfinite(f.limit_world) ? f.limit_world : 0);
  header.set_coordinates(setup.packing.doubles ? v1::VALUE_TYPE_FLOAT64 : v1::VALUE_TYPE_FLOAT32);
  const PointOutputs wanted = pointOutputsOf(a.outputs);
  header.set_closest_points(wanted.closest_points);
  header.set_closest_feature(wanted.features);
  header.set_gradient(wanted.gradients);

  PointFileOutputs outputs;
  if (Status s = outputs.open(a.outputs, setup.packing); !s.ok()) {
    ctx.err << "distband at: " << s.message() << "\n";
    return kExitFailure;
  }
  // The writer thread reads the query file a chunk at a time; a read error stops the stream (reported below).
  std::string read_error;
  std::vector<Vec3d> chunk;
  RemotePointsCallbacks cb;
  cb.next_chunk = [&](std::string* xyz) {
    chunk.clear();
    if (Status s = setup.points->next(size_t(a.chunk_points), &chunk); !s.ok()) {
      read_error = s.message();
      canceller.cancel();
      return false;
    }
    if (chunk.empty()) return false;
    PointResultBuffer::packValues(reinterpret_cast<const double*>(chunk.data()), 3 * chunk.size(), setup.packing, xyz);
    return true;
  };
  std::string write_error;
  cb.on_header = [&](const v1::PointsReplyHeader& h) {
    ctx.out << fmt::format("distband at: server {} query {}; sign: {} ({}); limit {}\n", connection_args.server,
                           h.query_id(), v1::SignMode_Name(h.sign()), h.sign_reason(),
                           std::isfinite(h.limit()) ? fmt::format("{:g}", h.limit()) : std::string("none"));
    ctx.out.flush();
    return true;
  };
  cb.on_results = [&](const v1::PointsResults& r) {
    if (Status s = outputs.append(r.points(), r.distance(), r.closest_points(), r.closest_feature(), r.gradient());
        !s.ok()) {
      write_error = s.message();
      return false;
    }
    return true;
  };
  RemoteQueryOptions qo;
  qo.canceller = &canceller;
  if (deadline)
    qo.deadline = std::max(std::chrono::milliseconds(1),
                           std::chrono::ceil<std::chrono::milliseconds>(*deadline - std::chrono::steady_clock::now()));
  const RemotePointsResult result = connection->queryPoints(header, cb, qo);
  if (!read_error.empty()) {
    outputs.abandon();
    return usage(read_error);
  }
  if (!write_error.empty()) {
    outputs.abandon();
    ctx.err << "distband at: " << write_error << "\n";
    return kExitFailure;
  }
  if (!result.status.ok()) {
    outputs.abandon();
    if (watch.deadlinePassed() || result.status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
      ctx.err << "distband at: the deadline (--deadline) passed; nothing written\n";
      return kExitFailure;
    }
    if (canceller.cancelled()) {
      ctx.err << "distband at: interrupted; nothing written\n";
      return kExitInterrupted;
    }
    ctx.err << "distband at: " << describe(result.status) << "\n";
    return result.status.error_code() == grpc::StatusCode::CANCELLED ? kExitFailure : exitCodeOf(result.status);
  }
  std::vector<std::string> lines;
  if (Status s = outputs.finish(&lines); !s.ok()) {
    ctx.err << "distband at: " << s.message() << "\n";
    return kExitFailure;
  }
  for (const std::string& line : lines) ctx.out << line << "\n";
  const v1::PointsSummary& sum = result.summary;
  ctx.out << fmt::format(
      "done: {} points in {} chunks, {:.3f} s ({:.3g} points/s); server: search {:.3f} s, compute {:.3f} s, "
      "{} beyond the limit\n",
      sum.points(), sum.chunks(), result.total_seconds,
      result.total_seconds > 0 ? double(sum.points()) / result.total_seconds : 0.0, sum.search_seconds(),
      sum.compute_seconds(), sum.beyond_limit());
  return kExitOk;
}

}  // namespace

AtRemote remoteAt() {
  auto connection = std::make_shared<ConnectionArgs>();
  AtRemote r;
  r.add_flags = [connection](CLI::App* cmd) { addConnectionFlags(cmd, connection.get()); };
  r.run = [connection](const AtArgs& a, const CliContext& ctx) { return runRemoteAt(a, *connection, ctx); };
  return r;
}

}  // namespace distband
