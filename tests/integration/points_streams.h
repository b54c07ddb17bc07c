// What the QueryPoints integration tests share (points_test.cc, one server; scale_out_points_test.cc, a coordinator):
// packed query points, query points around a mesh, raw streams of hand-made messages and their refusals.
#pragma once

#include <algorithm>
#include <chrono>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "core/mesh/triangle_mesh.h"
#include "core/points/point_results.h"
#include "core/types.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/request_id.h"

namespace distband::points_streams {

/// Points as a chunk's xyz bytes: float64 with `doubles`, else float32.
inline std::string packXyz(const std::vector<Vec3d>& p, bool doubles) {
  std::string out;
  PointResultBuffer::packValues(reinterpret_cast<const double*>(p.data()), 3 * p.size(), {doubles, false}, &out);
  return out;
}

inline void bounds(const TriangleMesh& mesh, Vec3d* lo, Vec3d* hi) {
  *lo = *hi = mesh.vertices[0];
  for (const Vec3d& v : mesh.vertices) {
    *lo = {std::min(lo->x, v.x), std::min(lo->y, v.y), std::min(lo->z, v.z)};
    *hi = {std::max(hi->x, v.x), std::max(hi->y, v.y), std::max(hi->z, v.z)};
  }
}

/// Query points: half uniform in the bounding box grown by 10 % a side, half Gaussian around surface points (sigma 1 %
/// of the diagonal).
inline std::vector<Vec3d> samplePoints(const TriangleMesh& mesh, size_t n, uint32_t seed) {
  Vec3d lo, hi;
  bounds(mesh, &lo, &hi);
  const Vec3d size = hi - lo;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, 0.01 * size.length());
  std::vector<Vec3d> p(n);
  for (size_t i = 0; i < n; ++i) {
    if (i % 2 == 0) {
      p[i] = {lo.x - 0.1 * size.x + 1.2 * size.x * u(rng), lo.y - 0.1 * size.y + 1.2 * size.y * u(rng),
              lo.z - 0.1 * size.z + 1.2 * size.z * u(rng)};
    } else {
      const auto& t = mesh.triangles[size_t(u(rng) * double(mesh.triangles.size())) % mesh.triangles.size()];
      const double a = u(rng), b = u(rng) * (1 - a);
      const Vec3d s = mesh.vertices[t[0]] * (1 - a - b) + mesh.vertices[t[1]] * a + mesh.vertices[t[2]] * b;
      p[i] = s + Vec3d{g(rng), g(rng), g(rng)};
    }
  }
  return p;
}

inline v1::PointsRequest chunkOf(const std::vector<Vec3d>& p, bool doubles = false) {
  v1::PointsRequest m;
  m.mutable_chunk()->set_xyz(packXyz(p, doubles));
  return m;
}

/// A raw stream: the messages given, then half-close; the status and the number of results.
struct RawResult {
  grpc::Status status;
  int results = 0;
};
inline RawResult rawStream(const std::shared_ptr<grpc::Channel>& channel,
                           const std::vector<v1::PointsRequest>& messages, const std::string& request_id = {}) {
  auto stub = v1::DistanceField::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  if (!request_id.empty()) context.AddMetadata(kRequestIdHeader, request_id);
  auto stream = stub->QueryPoints(&context);
  for (const v1::PointsRequest& m : messages)
    if (!stream->Write(m)) break;
  stream->WritesDone();
  RawResult r;
  v1::PointsReply reply;
  while (stream->Read(&reply)) r.results += reply.has_results();
  r.status = stream->Finish();
  return r;
}

inline void expectRefused(const RawResult& r, grpc::StatusCode code, const std::vector<std::string>& words) {
  EXPECT_EQ(r.status.error_code(), code) << r.status.error_message();
  for (const std::string& w : words)
    EXPECT_NE(r.status.error_message().find(w), std::string::npos) << r.status.error_message() << " lacks " << w;
}

}  // namespace distband::points_streams
