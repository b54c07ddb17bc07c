#include "core/io/vdb_file.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <random>

#include <blosc.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {
namespace {

// The file format written here is OpenVDB's version 224 (io::Archive, OpenVDB 10), byte for byte where it matters
// to readers: header, grid descriptors with stream offsets, per-grid compression flags, metadata, transform,
// topology (root tiles and children, node child/value masks and tile values), then the leaf buffers.
constexpr int64_t kVdbMagic = 0x56444220;     // " BDV"
constexpr uint32_t kFileVersion = 224;
constexpr uint32_t kLibraryMajor = 10, kLibraryMinor = 0;  // the writer whose output this reproduces
constexpr uint32_t kCompressActiveMask = 0x2, kCompressBlosc = 0x4;
constexpr uint32_t kCompression = kCompressActiveMask | kCompressBlosc;  // OpenVDB's default for every grid class
// Per-node indicator of which inactive values are stored (OpenVDB's io::MaskCompress).
enum : int8_t {
  kNoMaskOrInactiveVals,     // none, or all inactive values are +background
  kNoMaskAndMinusBg,         // all inactive values are -background
  kNoMaskAndOneInactiveVal,  // all inactive values are one other value (stored)
  kMaskAndNoInactiveVals,    // a mask selects -background (0) or +background (1)
  kMaskAndOneInactiveVal,    // a mask selects the stored value (0) or +background (1)
  kMaskAndTwoInactiveVals,   // a mask selects between two stored values
  kNoMaskAndAllVals,         // more than two inactive values: every value is stored
};

template <class T>
void put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}
void putString(std::string& out, const std::string& s) {
  put(out, uint32_t(s.size()));
  out += s;
}

// OpenVDB's writeData with Blosc: the compressed size then the bytes, or minus the size then the raw bytes when Blosc
// cannot compress them. Blosc's parameters are OpenVDB's (LZ4, byte shuffle of 4-byte words, level 9, one block).
void putBlosc(std::string& out, const void* data, size_t bytes) {
  const size_t capacity = bytes + BLOSC_MAX_OVERHEAD;
  const size_t at = out.size() + sizeof(int64_t);
  out.resize(at + capacity);
  const int n = blosc_compress_ctx(9, 1, sizeof(float), bytes, data, out.data() + at, capacity, "lz4", bytes, 1);
  if (n > 0) {
    const int64_t packed = n;
    std::memcpy(out.data() + at - sizeof(int64_t), &packed, sizeof(int64_t));
    out.resize(at + size_t(n));
  } else {
    const int64_t raw = -int64_t(bytes);
    std::memcpy(out.data() + at - sizeof(int64_t), &raw, sizeof(int64_t));
    out.resize(at);
    out.append(static_cast<const char*>(data), bytes);
  }
}

bool bitOn(const uint64_t* words, size_t i) { return (words[i >> 6] >> (i & 63)) & 1; }

// OpenVDB's io::writeCompressedValues with active-mask and Blosc compression: `values` holds every entry of a node
// (zero at child entries), `value_mask` its active entries, `child_mask` (null for leaves) its children.
template <class T>
void putNodeValues(std::string& out, const T* values, size_t count, const uint64_t* value_mask,
                   const uint64_t* child_mask, T background) {
  T inactive[2] = {background, background};
  int unique = 0;
  for (size_t i = 0; i < count && unique < 3; ++i) {
    if (bitOn(value_mask, i) || (child_mask && bitOn(child_mask, i))) continue;
    const T v = values[i];
    if ((unique > 0 && v == inactive[0]) || (unique > 1 && v == inactive[1])) continue;
    if (unique < 2) inactive[unique] = v;
    ++unique;
  }
  const T minus_bg = T(-background);
  int8_t meta = kNoMaskOrInactiveVals;
  if (unique == 1) {
    if (!(inactive[0] == background)) meta = inactive[0] == minus_bg ? kNoMaskAndMinusBg : kNoMaskAndOneInactiveVal;
  } else if (unique == 2) {
    if (!(inactive[0] == background) && !(inactive[1] == background)) {
      meta = kMaskAndTwoInactiveVals;
    } else if (inactive[1] == background) {
      meta = inactive[0] == minus_bg ? kMaskAndNoInactiveVals : kMaskAndOneInactiveVal;
    } else {  // inactive[0] is the background
      meta = inactive[1] == minus_bg ? kMaskAndNoInactiveVals : kMaskAndOneInactiveVal;
      std::swap(inactive[0], inactive[1]);
    }
  } else if (unique > 2) {
    meta = kNoMaskAndAllVals;
  }
  put(out, meta);
  if (meta == kNoMaskAndOneInactiveVal || meta == kMaskAndOneInactiveVal || meta == kMaskAndTwoInactiveVals) {
    put(out, inactive[0]);
    if (meta == kMaskAndTwoInactiveVals) put(out, inactive[1]);
  }
  if (meta == kNoMaskAndAllVals) {
    putBlosc(out, values, count * sizeof(T));
    return;
  }
  // Only the active values, and for the mask kinds the mask that selects each inactive value. Scratch on the stack
  // for leaves (this runs once per leaf, on every thread), on the heap for the few internal nodes.
  const bool selects = meta == kMaskAndNoInactiveVals || meta == kMaskAndOneInactiveVal || meta == kMaskAndTwoInactiveVals;
  std::array<T, kBrickVoxels> active_leaf;
  std::array<uint64_t, kBrickVoxels / 64> selection_leaf{};
  std::vector<T> active_node;
  std::vector<uint64_t> selection_node;
  T* active = active_leaf.data();
  uint64_t* selection = selection_leaf.data();
  if (count > size_t(kBrickVoxels)) {
    active_node.resize(count);
    selection_node.assign(count / 64, 0);
    active = active_node.data();
    selection = selection_node.data();
  }
  size_t n = 0;
  for (size_t w = 0; w < count / 64; ++w) {
    const uint64_t on = value_mask[w];
    if (on == ~uint64_t(0)) {
      std::memcpy(active + n, values + w * 64, 64 * sizeof(T));
      n += 64;
      continue;
    }
    for (size_t b = 0; b < 64; ++b) {
      const size_t i = w * 64 + b;
      if ((on >> b) & 1) active[n++] = values[i];
      else if (selects && values[i] == inactive[1]) selection[w] |= uint64_t(1) << b;
    }
  }
  if (selects) out.append(reinterpret_cast<const char*>(selection), count / 64 * sizeof(uint64_t));
  putBlosc(out, active, n * sizeof(T));
}

template <class T>
std::string treeTypeName();
template <>
std::string treeTypeName<float>() { return "Tree_float_5_4_3"; }
template <>
std::string treeTypeName<int32_t>() { return "Tree_int32_5_4_3"; }
template <>
std::string treeTypeName<int64_t>() { return "Tree_int64_5_4_3"; }

// A node's table as OpenVDB writes it: child mask, value mask (no active tiles here), then the tile values.
template <class T, class Node>
void putNodeTopology(std::string& out, const Node& node, const VdbTree<T>& tree) {
  const size_t count = node.child.size() * 64;
  out.append(reinterpret_cast<const char*>(node.child.data()), node.child.size() * sizeof(uint64_t));
  const std::vector<uint64_t> no_active(node.child.size(), 0);
  out.append(reinterpret_cast<const char*>(no_active.data()), no_active.size() * sizeof(uint64_t));
  std::vector<T> values(count);
  for (size_t i = 0; i < count; ++i)
    values[i] = node.isChild(int(i)) ? T(0) : tree.tileValue(node.isNegative(int(i)));
  putNodeValues(out, values.data(), count, no_active.data(), node.child.data(), tree.background());
}

class FileOut {
 public:
  explicit FileOut(const std::string& path) : path_(path), os_(path, std::ios::binary | std::ios::trunc) {}
  bool ok() const { return bool(os_); }
  void write(const std::string& bytes) { os_.write(bytes.data(), std::streamsize(bytes.size())); }
  int64_t position() { return int64_t(os_.tellp()); }
  void patch(int64_t at, const std::string& bytes) {
    const auto end = os_.tellp();
    os_.seekp(at);
    write(bytes);
    os_.seekp(end);
  }
  /// kIoError when any write (or the close) failed.
  Status close() {
    os_.close();
    if (!os_)
      return Status::IoError(
          fmt::format("{}: cannot write the VDB file (disk full, or the path is not writable)", path_));
    return Status::Ok();
  }

 private:
  std::string path_;
  std::ofstream os_;
};

std::string uuid() {
  std::random_device rd;
  std::string hex;
  for (int i = 0; i < 4; ++i) hex += fmt::format("{:08X}", uint32_t(rd()));
  return hex.substr(0, 8) + "-" + hex.substr(8, 4) + "-" + hex.substr(12, 4) + "-" + hex.substr(16, 4) + "-" +
         hex.substr(20, 12);
}

void putMeta(std::string& out, const std::string& name, const VdbMetaValue& value) {
  putString(out, name);
  std::visit(
      [&](const auto& v) {
        using V = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<V, bool>) {
          putString(out, "bool");
          put(out, uint32_t(1));
          put(out, uint8_t(v ? 1 : 0));
        } else if constexpr (std::is_same_v<V, int32_t>) {
          putString(out, "int32");
          put(out, uint32_t(4));
          put(out, v);
        } else if constexpr (std::is_same_v<V, int64_t>) {
          putString(out, "int64");
          put(out, uint32_t(8));
          put(out, v);
        } else if constexpr (std::is_same_v<V, std::string>) {
          putString(out, "string");
          putString(out, v);  // size then bytes, as StringMetadata writes itself
        } else {
          putString(out, "vec3i");
          put(out, uint32_t(12));
          put(out, v.x), put(out, v.y), put(out, v.z);
        }
      },
      value);
}

template <class T>
void writeGrid(FileOut& file, const VdbGridOut& g, const VdbTree<T>& tree, const VdbTransformOut& xform) {
  std::string out;
  putString(out, g.name);
  putString(out, treeTypeName<T>());
  putString(out, "");  // no instance parent
  file.write(out);
  const int64_t offsets_at = file.position();
  file.write(std::string(3 * sizeof(int64_t), '\0'));  // grid, block and end positions, patched below
  const int64_t grid_pos = file.position();

  out.clear();
  put(out, kCompression);
  std::map<std::string, VdbMetaValue> meta(g.metadata.begin(), g.metadata.end());
  if (g.level_set) meta["class"] = std::string("level set");
  meta["name"] = g.name;
  Coord lo, hi;
  if (tree.activeBounds(&lo, &hi)) meta["file_bbox_min"] = lo, meta["file_bbox_max"] = hi;
  meta["file_voxel_count"] = int64_t(tree.activeVoxels());
  meta["file_compression"] = std::string("blosc + active values");
  put(out, uint32_t(meta.size()));
  for (const auto& [name, value] : meta) putMeta(out, name, value);
  // (Uniform)ScaleTranslateMap, both stored alike: translation, scale, voxel size, 1 / scale, 1 / scale²,
  // 1 / (2 scale), each a vector over the axes.
  const Vec3d s = xform.spacing;
  const bool uniform = s.x == s.y && s.y == s.z;
  putString(out, uniform ? "UniformScaleTranslateMap" : "ScaleTranslateMap");
  const Vec3d inv{1.0 / s.x, 1.0 / s.y, 1.0 / s.z};
  for (double v : {xform.translation.x, xform.translation.y, xform.translation.z, s.x, s.y, s.z, std::abs(s.x),
                   std::abs(s.y), std::abs(s.z), inv.x, inv.y, inv.z, inv.x * inv.x, inv.y * inv.y, inv.z * inv.z,
                   0.5 * inv.x, 0.5 * inv.y, 0.5 * inv.z})
    put(out, v);

  // Topology: one buffer; the root's background, tiles and children; depth first through the nodes.
  put(out, int32_t(1));
  put(out, tree.background());
  put(out, uint32_t(tree.rootTiles().size()));
  put(out, uint32_t(tree.nodes2().size()));
  for (const auto& t : tree.rootTiles()) {
    put(out, t.origin.x), put(out, t.origin.y), put(out, t.origin.z);
    put(out, tree.tileValue(t.negative));
    put(out, uint8_t(0));  // inactive
  }
  const auto& leaves = tree.leaves();
  const auto& nodes1 = tree.nodes1();
  for (size_t i2 = 0; i2 < tree.nodes2().size(); ++i2) {
    const auto& n2 = tree.nodes2()[i2];
    put(out, n2.origin.x), put(out, n2.origin.y), put(out, n2.origin.z);
    putNodeTopology(out, n2, tree);
    const size_t end1 = i2 + 1 < tree.nodes2().size() ? tree.nodes2()[i2 + 1].first : nodes1.size();
    for (size_t i1 = n2.first; i1 < end1; ++i1) {
      putNodeTopology(out, nodes1[i1], tree);
      const size_t end0 = i1 + 1 < nodes1.size() ? nodes1[i1 + 1].first : leaves.size();
      for (size_t l = nodes1[i1].first; l < end0; ++l)
        out.append(reinterpret_cast<const char*>(leaves[l]->mask.words.data()), sizeof(leaves[l]->mask.words));
    }
    file.write(out);
    out.clear();
  }
  file.write(out);
  const int64_t block_pos = file.position();

  // Leaf buffers: the value mask, then the compressed values; encoded in parallel a chunk at a time.
  constexpr size_t kChunk = 4096;
  std::vector<std::string> encoded;
  for (size_t c0 = 0; c0 < leaves.size(); c0 += kChunk) {
    const size_t c1 = std::min(leaves.size(), c0 + kChunk);
    encoded.assign(c1 - c0, std::string());
    tbb::parallel_for(tbb::blocked_range<size_t>(c0, c1, 16), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t l = r.begin(); l != r.end(); ++l) {
        std::string& e = encoded[l - c0];
        const auto& leaf = *leaves[l];
        e.reserve(sizeof(leaf.mask.words) + 16 + kBrickVoxels * sizeof(T));
        e.append(reinterpret_cast<const char*>(leaf.mask.words.data()), sizeof(leaf.mask.words));
        putNodeValues(e, leaf.values.data(), size_t(kBrickVoxels), leaf.mask.words.data(), nullptr, tree.background());
      }
    });
    for (const std::string& e : encoded) file.write(e);
  }
  const int64_t end_pos = file.position();
  out.clear();
  put(out, grid_pos), put(out, block_pos), put(out, end_pos);
  file.patch(offsets_at, out);
}

}  // namespace

Status writeVdbFile(const std::string& path, const std::vector<VdbGridOut>& grids, const VdbTransformOut& xform) {
  for (const VdbGridOut& g : grids) {
    const int trees = (g.float_tree != nullptr) + (g.int32_tree != nullptr) + (g.int64_tree != nullptr);
    if (trees != 1) return Status::InvalidArgument(fmt::format("{}: grid '{}' needs exactly one tree", path, g.name));
    if ((g.float_tree && !g.float_tree->sealed()) || (g.int32_tree && !g.int32_tree->sealed()) ||
        (g.int64_tree && !g.int64_tree->sealed()))
      return Status::InvalidArgument(fmt::format("{}: grid '{}' is not sealed", path, g.name));
  }
  FileOut file(path);
  if (!file.ok()) return Status::IoError(fmt::format("{}: cannot open for writing", path));
  std::string out;
  put(out, kVdbMagic);
  put(out, kFileVersion);
  put(out, kLibraryMajor), put(out, kLibraryMinor);
  put(out, uint8_t(1));  // the grid descriptors hold stream offsets
  out += uuid();
  put(out, uint32_t(0));  // no file-level metadata
  put(out, int32_t(grids.size()));
  file.write(out);
  for (const VdbGridOut& g : grids) {
    if (g.float_tree) writeGrid(file, g, *g.float_tree, xform);
    if (g.int32_tree) writeGrid(file, g, *g.int32_tree, xform);
    if (g.int64_tree) writeGrid(file, g, *g.int64_tree, xform);
  }
  return file.close();
}

}  // namespace distband
