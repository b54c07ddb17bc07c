#include "core/mesh/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <unordered_map>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

namespace distband {
namespace {

struct PositionKey {
  uint64_t b[3];
  bool operator==(const PositionKey& o) const { return b[0] == o.b[0] && b[1] == o.b[1] && b[2] == o.b[2]; }
};
struct PositionHash {
  size_t operator()(const PositionKey& k) const {
    uint64_t h = 0x9E3779B97F4A7C15ull;
    for (uint64_t v : k.b) h = (h ^ v) * 0xBF58476D1CE4E5B9ull, h ^= h >> 31;
    return static_cast<size_t>(h);
  }
};
PositionKey keyOf(const Vec3d& v) {
  PositionKey k;
  const double c[3] = {v.x + 0.0, v.y + 0.0, v.z + 0.0};  // + 0.0 folds -0 into +0
  for (int i = 0; i < 3; ++i) std::memcpy(&k.b[i], &c[i], sizeof(double));
  return k;
}

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// Assimp checks neither the face count an OFF header promises nor the triangle count a binary STL header
// promises against what the file holds (it silently loads a truncated file), so check the headers here.
std::string checkDeclaredCounts(const std::string& path, const std::string& ext) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return {};
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return {};
  std::string error;
  if (ext == ".stl") {
    char head[84];
    if (std::fread(head, 1, 84, f) == 84 && std::strncmp(head, "solid", 5) != 0) {
      uint32_t n = 0;
      std::memcpy(&n, head + 80, 4);
      const uint64_t need = 84 + uint64_t(n) * 50;
      if (size < need)
        error = fmt::format("truncated binary STL: the header declares {} triangles ({} bytes) but the file has {} bytes",
                            n, need, size);
    }
  } else if (ext == ".off") {
    // Header: "OFF" (possibly followed by the counts on the same line), then "nv nf ne"; '#' starts a comment.
    // Assimp neither checks the counts against the data nor rejects out-of-range face indices.
    std::string text;
    text.resize(std::min<uint64_t>(size, uint64_t(1) << 30));
    text.resize(std::fread(text.data(), 1, text.size(), f));
    size_t pos = 0;
    int64_t lines = 0;
    long nv = -1, nf = -1;
    bool keyword = false;
    while (pos < text.size() && error.empty()) {
      size_t eol = text.find('\n', pos);
      if (eol == std::string::npos) eol = text.size();
      std::string line = text.substr(pos, eol - pos);
      pos = eol + 1;
      if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
      if (line.find_first_not_of(" \t\r\f\v") == std::string::npos) continue;
      if (nv < 0) {
        std::string rest = line;
        if (auto k = rest.find("OFF"); k != std::string::npos && !keyword) {
          keyword = true;
          if (rest.find("BINARY") != std::string::npos) break;  // binary OFF: left to assimp
          rest = rest.substr(k + 3);
        }
        long a = -1, b = -1;
        if (std::sscanf(rest.c_str(), "%ld %ld", &a, &b) == 2) {
          if (a < 0 || b < 0) error = fmt::format("negative counts in the OFF header ({} vertices, {} faces)", a, b);
          nv = a, nf = b;
        }
        continue;
      }
      ++lines;
      if (lines > nv && lines <= nv + nf) {  // a face line: "k i1 ... ik"
        const char* p = line.c_str();
        char* end = nullptr;
        const long k = std::strtol(p, &end, 10);
        if (end == p || k < 1) {
          error = fmt::format("face {} has no vertex count", lines - nv - 1);
          break;
        }
        p = end;
        for (long i = 0; i < k; ++i) {
          const long idx = std::strtol(p, &end, 10);
          if (end == p) {
            error = fmt::format("face {} declares {} vertices but lists {}", lines - nv - 1, k, i);
            break;
          }
          if (idx < 0 || idx >= nv) {
            error = fmt::format("face {} refers to vertex {} but the file has {} vertices", lines - nv - 1, idx, nv);
            break;
          }
          p = end;
        }
      }
    }
    if (error.empty() && nv >= 0 && nf >= 0 && lines < nv + nf)
      error = fmt::format("truncated OFF file: the header declares {} vertices and {} faces but only {} data lines follow",
                          nv, nf, lines);
  }
  std::fclose(f);
  return error;
}

void collect(const aiScene* scene, const aiNode* node, const aiMatrix4x4& parent, TriangleMesh* out,
             int64_t* non_triangles, std::string* error) {
  const aiMatrix4x4 xf = parent * node->mTransformation;
  for (unsigned m = 0; m < node->mNumMeshes && error->empty(); ++m) {
    if (node->mMeshes[m] >= scene->mNumMeshes) {
      *error = "the scene names a mesh that does not exist";
      return;
    }
    const aiMesh* mesh = scene->mMeshes[node->mMeshes[m]];
    const size_t base = out->vertices.size();
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D p = xf * mesh->mVertices[v];
      out->vertices.push_back({double(p.x), double(p.y), double(p.z)});
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices < 3 || !face.mIndices) {
        ++*non_triangles;
        continue;
      }
      for (unsigned i = 0; i < face.mNumIndices; ++i)
        if (face.mIndices[i] >= mesh->mNumVertices) {
          *error = fmt::format("face {} refers to vertex {} but the mesh has {} vertices", f, face.mIndices[i],
                               mesh->mNumVertices);
          return;
        }
      // Polygons become a fan around their first corner (exact for the convex polygons mesh files hold).
      for (unsigned i = 1; i + 1 < face.mNumIndices; ++i)
        out->triangles.push_back({static_cast<uint32_t>(base + face.mIndices[0]),
                                  static_cast<uint32_t>(base + face.mIndices[i]),
                                  static_cast<uint32_t>(base + face.mIndices[i + 1])});
    }
  }
  for (unsigned c = 0; c < node->mNumChildren && error->empty(); ++c)
    collect(scene, node->mChildren[c], xf, out, non_triangles, error);
}

}  // namespace

std::string MeshReport::summary() const {
  return fmt::format("{} vertices, {} triangles, {} degenerate skipped, {} boundary edges, {} non-manifold edges{}",
                     vertices, triangles, degenerate, boundary_edges, non_manifold_edges,
                     non_triangles ? fmt::format(", {} point/line primitives skipped", non_triangles) : "");
}

std::string validateMesh(TriangleMesh* mesh, MeshReport* report) {
  MeshReport r;
  if (mesh->vertices.empty() || mesh->triangles.empty()) return "the mesh has no triangles";
  for (size_t i = 0; i < mesh->vertices.size(); ++i) {
    const Vec3d& v = mesh->vertices[i];
    if (!(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z)))
      return fmt::format("vertex {} has a non-finite coordinate ({}, {}, {})", i, v.x, v.y, v.z);
  }
  const size_t nv = mesh->vertices.size();
  for (size_t t = 0; t < mesh->triangles.size(); ++t)
    for (uint32_t idx : mesh->triangles[t])
      if (idx >= nv) return fmt::format("triangle {} refers to vertex {} but there are {} vertices", t, idx, nv);

  // Weld identical positions.
  std::unordered_map<PositionKey, uint32_t, PositionHash> index_of;
  index_of.reserve(nv);
  std::vector<uint32_t> remap(nv);
  std::vector<Vec3d> welded;
  for (size_t i = 0; i < nv; ++i) {
    auto [it, inserted] = index_of.try_emplace(keyOf(mesh->vertices[i]), static_cast<uint32_t>(welded.size()));
    if (inserted) welded.push_back(mesh->vertices[i]);
    remap[i] = it->second;
  }
  // Drop degenerate triangles (repeated corner, or zero area relative to the longest edge).
  std::vector<std::array<uint32_t, 3>> kept;
  kept.reserve(mesh->triangles.size());
  for (auto t : mesh->triangles) {
    for (auto& i : t) i = remap[i];
    bool degenerate = t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
    if (!degenerate) {
      const Vec3d &a = welded[t[0]], &b = welded[t[1]], &c = welded[t[2]];
      const double area2 = (b - a).cross(c - a).length();
      const double longest = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
      degenerate = !(area2 > 1e-12 * longest);
    }
    if (degenerate)
      ++r.degenerate;
    else
      kept.push_back(t);
  }
  if (kept.empty()) return fmt::format("all {} triangles are degenerate (zero area)", r.degenerate);
  // Drop unreferenced vertices, keeping first-use order stable by index.
  std::vector<uint32_t> used(welded.size(), UINT32_MAX);
  std::vector<Vec3d> vertices;
  for (auto& t : kept)
    for (auto& i : t) {
      if (used[i] == UINT32_MAX) {
        used[i] = static_cast<uint32_t>(vertices.size());
        vertices.push_back(welded[i]);
      }
      i = used[i];
    }
  // Edge statistics.
  std::vector<uint64_t> edges;
  edges.reserve(kept.size() * 3);
  for (const auto& t : kept)
    for (int e = 0; e < 3; ++e) {
      const uint64_t a = t[e], b = t[(e + 1) % 3];
      edges.push_back(std::min(a, b) << 32 | std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) ++r.boundary_edges;
    if (j - i > 2) ++r.non_manifold_edges;
    i = j;
  }
  r.bbox_min = r.bbox_max = vertices[0];
  for (const Vec3d& v : vertices) {
    r.bbox_min = {std::min(r.bbox_min.x, v.x), std::min(r.bbox_min.y, v.y), std::min(r.bbox_min.z, v.z)};
    r.bbox_max = {std::max(r.bbox_max.x, v.x), std::max(r.bbox_max.y, v.y), std::max(r.bbox_max.z, v.z)};
  }
  r.vertices = static_cast<int64_t>(vertices.size());
  r.triangles = static_cast<int64_t>(kept.size());
  mesh->vertices = std::move(vertices);
  mesh->triangles = std::move(kept);
  if (report) {
    r.non_triangles = report->non_triangles;
    *report = r;
  }
  return {};
}

std::string loadMesh(const std::string& path, TriangleMesh* mesh, MeshReport* report) {
  auto fail = [&](const std::string& problem) { return fmt::format("{}: {}", path, problem); };
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) return fail("no such file");
  if (!std::filesystem::is_regular_file(status)) return fail("not a regular file");
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return fail("cannot read the file size");
  if (size == 0) return fail("the file is empty");
  const std::string ext = lowerExtension(path);
  if (ext != ".obj" && ext != ".off" && ext != ".ply" && ext != ".stl")
    return fail(fmt::format("unsupported mesh format '{}' (expected .obj, .off, .ply or .stl)", ext));
  if (std::string e = checkDeclaredCounts(path, ext); !e.empty()) return fail(e);

  Assimp::Importer importer;
  // Keep only what we read: no normals, colours, UVs, materials, cameras or lights.
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_COLORS |
                                                          aiComponent_TEXCOORDS | aiComponent_MATERIALS);
  const aiScene* scene = nullptr;
  try {
    // No aiProcess_Triangulate: on a file whose faces disagree with their declared primitive types (a PLY cut
    // inside a face list) it fails an internal assertion and aborts the process. Polygons are fanned in collect().
    scene = importer.ReadFile(path, aiProcess_JoinIdenticalVertices | aiProcess_ValidateDataStructure);
  } catch (const std::exception& e) {
    return fail(fmt::format("cannot parse the file: {}", e.what()));
  }
  if (!scene) {
    std::string why = importer.GetErrorString();
    return fail(why.empty() ? "cannot parse the file" : fmt::format("cannot parse the file: {}", why));
  }
  if (!scene->mRootNode || scene->mNumMeshes == 0) return fail("the file holds no mesh");
  TriangleMesh loaded;
  MeshReport r;
  std::string error;
  collect(scene, scene->mRootNode, aiMatrix4x4(), &loaded, &r.non_triangles, &error);
  if (!error.empty()) return fail(error);
  if (std::string e = validateMesh(&loaded, &r); !e.empty()) return fail(e);
  *mesh = std::move(loaded);
  if (report) *report = r;
  return {};
}

}  // namespace distband
