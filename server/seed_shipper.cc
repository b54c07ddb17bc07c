#include "server/seed_shipper.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/mesh/ply_writer.h"
#include "server/asset_parsing.h"
#include "server/grpc_status.h"
#include "server/log_line.h"

namespace distband {
namespace {

constexpr size_t kUploadChunkBytes = size_t(1) << 20;

std::string boxKey(const VoxelBox& b) {
  return fmt::format("{},{},{},{},{},{}", b.min.x, b.min.y, b.min.z, b.dims.x, b.dims.y, b.dims.z);
}

/// The window's voxels of a whole-grid volume (x fastest, its element type).
std::string cropVolume(const LabelVolume& volume, const VoxelBox& window) {
  const Coord dims = volume.dims();
  const size_t w = volume.elementBytes();
  std::string out(size_t(window.voxelCount()) * w, '\0');
  size_t o = 0;
  for (int z = window.min.z; z < window.end().z; ++z)
    for (int y = window.min.y; y < window.end().y; ++y) {
      const size_t row = ((size_t(z) * dims.y + y) * dims.x + window.min.x) * w;
      std::copy_n(reinterpret_cast<const char*>(volume.bytes().data()) + row, size_t(window.dims.x) * w, out.data() + o);
      o += size_t(window.dims.x) * w;
    }
  return out;
}

/// Squared index-space distance from p to the box's voxels.
double dist2ToBox(const Vec3d& p, const VoxelBox& b) {
  auto axis = [](double v, int lo, int hi) { return v < lo ? lo - v : (v > hi ? v - hi : 0.0); };
  const double dx = axis(p.x, b.min.x, b.end().x - 1), dy = axis(p.y, b.min.y, b.end().y - 1),
               dz = axis(p.z, b.min.z, b.end().z - 1);
  return dx * dx + dy * dy + dz * dz;
}

template <typename Chunk>
Status streamUpload(std::unique_ptr<grpc::ClientWriter<Chunk>> writer, std::string_view bytes, Chunk first,
                    const v1::UploadReply& reply, const std::string& id) {
  for (size_t off = 0; off == 0 || off < bytes.size(); off += kUploadChunkBytes) {
    Chunk chunk = off == 0 ? first : Chunk();
    const std::string_view piece = bytes.substr(off, kUploadChunkBytes);
    chunk.set_data(piece.data(), piece.size());
    if (!writer->Write(chunk)) break;
  }
  writer->WritesDone();
  const grpc::Status s = writer->Finish();
  if (!s.ok()) return fromGrpcStatus(s);
  if (reply.asset_id() != id)
    return Status::Internal(fmt::format("the replica named the upload {} instead of {}", reply.asset_id(), id));
  return Status::Ok();
}

}  // namespace

ShippedMesh canonicalMesh(const Asset& mesh) {
  ShippedMesh m;
  m.bytes = encodeBinaryPly(*mesh.mesh);
  m.id = meshAssetId(m.bytes, v1::MESH_FORMAT_PLY);
  m.name = mesh.name.substr(0, 200);
  return m;
}

Status ReplicaUploads::uploadMesh(const ShippedMesh& mesh, const std::vector<ReplicaPool::Replica>& replicas,
                                  ReplicaCalls& calls) {
  return upload(mesh.id, replicas, calls, [&](v1::DistanceField::Stub& stub, grpc::ClientContext* context) {
    v1::UploadReply reply;
    v1::UploadMeshChunk first;
    first.mutable_header()->set_format(v1::MESH_FORMAT_PLY);
    first.mutable_header()->set_total_bytes(mesh.bytes.size());
    first.mutable_header()->set_name(mesh.name);
    return streamUpload(stub.UploadMesh(context, &reply), mesh.bytes, first, reply, mesh.id);
  });
}

Status ReplicaUploads::uploadVolume(const v1::Dims& dims, VoxelType type, std::string_view bytes, const std::string& id,
                                    const std::vector<ReplicaPool::Replica>& replicas, ReplicaCalls& calls) {
  return upload(id, replicas, calls, [&](v1::DistanceField::Stub& stub, grpc::ClientContext* context) {
    v1::UploadReply reply;
    v1::UploadVolumeChunk first;
    *first.mutable_header()->mutable_dims() = dims;
    first.mutable_header()->set_element_type(v1VoxelType(type));
    return streamUpload(stub.UploadVolume(context, &reply), bytes, first, reply, id);
  });
}

bool ReplicaUploads::holds(const std::string& replica, const std::string& id) const {
  std::lock_guard lock(mu_);
  return uploaded_.count({replica, id}) > 0;
}

void ReplicaUploads::forget() {
  std::lock_guard lock(mu_);
  uploaded_.clear();
}

Status ReplicaUploads::upload(const std::string& id, const std::vector<ReplicaPool::Replica>& replicas,
                              ReplicaCalls& calls, const Upload& upload) {
  int present = 0;
  std::string last_error = "no replica resolves";
  for (const ReplicaPool::Replica& r : replicas) {
    if (Status stopped = calls.stopReason(); !stopped.ok()) return stopped;
    if (holds(r.address, id)) {
      ++present;
      continue;
    }
    auto stub = v1::DistanceField::NewStub(r.channel);
    grpc::ClientContext context;
    Status s;
    {
      ReplicaCalls::Call call(calls, &context);
      s = upload(*stub, &context);
    }
    std::lock_guard lock(mu_);
    if (s.ok()) {
      uploaded_.insert({r.address, id});
      ++present;
    } else {
      last_error = fmt::format("{}: {} {}", r.address, Status::codeName(s.code()), s.message());
      LogLine("SeedUpload")
          .text("request_id", calls.requestId())
          .text("asset", id.substr(0, 17))
          .text("replica", r.address)
          .status(s)
          .write(spdlog::level::warn);
    }
  }
  // A replica that missed it answers NOT_FOUND to a tile, which uploads again and retries.
  if (present > 0) return Status::Ok();
  return Status::Unavailable(
      fmt::format("could not pass the seeds on to any replica of --peers {} ({})", pool_.target(), last_error));
}

SeedShipper::SeedShipper(const ResolvedQuery& query, const ServerOptions& options, ReplicaPool& pool,
                         const std::vector<TilePlan>& tiles)
    : query_(query),
      options_(options),
      pool_(pool),
      tiles_(tiles),
      point_index_(tiles.size()),
      mesh_reach_(meshReach()),
      uploads_(pool) {
  if (query_.seed_kind != ResolvedQuery::SeedKind::kPoints) return;
  // Only points that can reach the tile within the limit, in their original order (ties go to the lower index).
  const double reach = query_.plan.limitVoxels(query_.grid) + 1;
  for (size_t t = 0; t < tiles_.size(); ++t)
    for (size_t i = 0; i < query_.points.size(); ++i)
      if (!std::isfinite(reach) || dist2ToBox(query_.grid.indexOf(query_.points[i]), tiles_[t].deliver) <= reach * reach)
        point_index_[t].push_back(uint32_t(i));
}

std::vector<bool> SeedShipper::meshReach() const {
  // With a limit, a tile no triangle comes within the limit of delivers nothing: its call is skipped (a surface in
  // a large grid touches few tiles). Each triangle marks the tiles its box, grown by the limit, overlaps.
  std::vector<bool> reach(tiles_.size(), true);
  const double limit = query_.plan.limitVoxels(query_.grid);
  if (query_.seed_kind != ResolvedQuery::SeedKind::kMesh || !std::isfinite(limit) || tiles_.empty()) return reach;
  std::fill(reach.begin(), reach.end(), false);
  // Tiles form a regular lattice (planTiles): the first tile's size is the step, ordered x fastest.
  const Coord step = tiles_[0].deliver.dims, dims = query_.grid.dims();
  const Coord count{(dims.x + step.x - 1) / step.x, (dims.y + step.y - 1) / step.y, (dims.z + step.z - 1) / step.z};
  const TriangleMesh& mesh = *query_.asset->mesh;
  auto range = [&](double lo, double hi, int s, int n, int* a, int* b) {
    *a = int(std::clamp(std::floor((lo - limit - 1) / s), 0.0, double(n - 1)));
    *b = int(std::clamp(std::floor((hi + limit + 1) / s), 0.0, double(n - 1)));
    return hi + limit + 1 >= 0 && lo - limit - 1 <= double(n) * s;
  };
  for (const auto& t : mesh.triangles) {
    const Vec3d a = query_.grid.indexOf(mesh.vertices[t[0]]), b = query_.grid.indexOf(mesh.vertices[t[1]]),
                c = query_.grid.indexOf(mesh.vertices[t[2]]);
    int x0, x1, y0, y1, z0, z1;
    if (!range(std::min({a.x, b.x, c.x}), std::max({a.x, b.x, c.x}), step.x, count.x, &x0, &x1) ||
        !range(std::min({a.y, b.y, c.y}), std::max({a.y, b.y, c.y}), step.y, count.y, &y0, &y1) ||
        !range(std::min({a.z, b.z, c.z}), std::max({a.z, b.z, c.z}), step.z, count.z, &z0, &z1))
      continue;
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) reach[(size_t(z) * count.y + y) * count.x + x] = true;
  }
  return reach;
}

bool SeedShipper::addSeeds(size_t tile, v1::QueryRequest* r) const {
  if (!mesh_reach_[tile]) return false;
  const VoxelBox& window = tiles_[tile].window;
  switch (query_.seed_kind) {
    case ResolvedQuery::SeedKind::kPoints: {
      r->mutable_points();  // set even when no point is within reach (then the tile is not sent)
      for (const uint32_t i : point_index_[tile]) {
        v1::Vec3* v = r->mutable_points()->add_points();
        v->set_x(query_.points[i].x);
        v->set_y(query_.points[i].y);
        v->set_z(query_.points[i].z);
      }
      return r->points().points_size() > 0;
    }
    case ResolvedQuery::SeedKind::kMesh:
      r->set_asset_id(mesh_.id);
      return true;
    case ResolvedQuery::SeedKind::kVolume: {
      if (const auto id = volume_ids_.find(boxKey(window)); id != volume_ids_.end()) {
        r->set_asset_id(id->second.second);
        return true;
      }
      *r->mutable_volume()->mutable_dims() = dimsOf(window.dims);
      r->mutable_volume()->set_element_type(v1VoxelType(query_.asset->volume.type()));
      r->mutable_volume()->set_mask(cropVolume(query_.asset->volume, window));
      const std::string& m = r->volume().mask();
      const bool any_seed = std::any_of(m.begin(), m.end(), [](char c) { return c != 0; });
      const bool any_free = std::any_of(m.begin(), m.end(), [](char c) { return c == 0; });
      return any_seed && (any_free || !query_.plan.inside_negative);
    }
  }
  return true;
}

Status SeedShipper::ship(ReplicaCalls& calls) {
  if (query_.seed_kind == ResolvedQuery::SeedKind::kMesh) {
    if (mesh_.bytes.empty()) mesh_ = canonicalMesh(*query_.asset);
    return uploads_.uploadMesh(mesh_, pool_.replicas(), calls);
  }
  if (query_.seed_kind == ResolvedQuery::SeedKind::kVolume) {
    const uint64_t inline_limit = options_.max_message_bytes / 2;
    const bool planning = !volumes_planned_;
    if (planning) {
      for (const TilePlan& t : tiles_)
        if (uint64_t(t.window.voxelCount()) * query_.asset->volume.elementBytes() > inline_limit)
          volume_ids_[boxKey(t.window)] = {t.window, ""};
      volumes_planned_ = true;
    }
    for (auto& [key, entry] : volume_ids_) {
      const std::string bytes = cropVolume(query_.asset->volume, entry.first);
      const v1::Dims dims = dimsOf(entry.first.dims);
      if (planning) entry.second = volumeAssetId(dims, query_.asset->volume.type(), bytes);
      if (Status s =
              uploads_.uploadVolume(dims, query_.asset->volume.type(), bytes, entry.second, pool_.replicas(), calls);
          !s.ok())
        return s;
    }
  }
  return Status::Ok();
}

void SeedShipper::forgetUploads() { uploads_.forget(); }

void SeedShipper::toQueryPointIds(size_t tile, v1::BrickBatch* batch) const {
  if (closestOf(query_.plan) != v1::CLOSEST_FEATURE_POINT) return;
  const std::vector<uint32_t>& point_index = point_index_[tile];
  for (v1::BrickData& b : *batch->mutable_bricks()) {
    std::string& ids = *b.mutable_closest();
    for (size_t at = 0; at + 4 <= ids.size(); at += 4) {
      int32_t id;
      std::memcpy(&id, ids.data() + at, 4);
      id = id >= 0 && size_t(id) < point_index.size() ? int32_t(point_index[size_t(id)]) : -1;
      std::memcpy(ids.data() + at, &id, 4);
    }
  }
}

}  // namespace distband
