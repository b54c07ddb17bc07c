// LabelVolume: a seed or label volume on a grid's voxels, as it comes — uint8 (and bool), uint16 or uint32 elements,
// label 0 the background.
// Contract:
//   * Elements are x fastest ([z][y][x] in C order, like a .npy of shape (Z, Y, X)), in the host's byte order (the
//     readers convert), held in a shared, immutable byte buffer, so an asset, a query's inputs and a tile's crop can
//     share or hand it over without copies.
//   * As seeds (the seed field) a voxel is a seed when its label is nonzero; as labels (the multi-label EDT) its label
//     is its value. visit() hands the elements to a function with their type, the one place the width is dispatched.
//   * make() checks the buffer against dims and type (kInvalidArgument saying what does not match); the constructor
//     throws std::invalid_argument for the same, as a broken precondition.
// Immutable; safe to share between threads.
#pragma once

#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "core/status.h"
#include "core/types.h"

namespace distband {

/// The element type of a volume (bool volumes are read as uint8).
enum class VoxelType : uint8_t { kUint8, kUint16, kUint32 };
inline constexpr VoxelType kVoxelTypes[] = {VoxelType::kUint8, VoxelType::kUint16, VoxelType::kUint32};

std::string_view voxelTypeName(VoxelType type);  ///< "uint8", "uint16", "uint32"
std::optional<VoxelType> parseVoxelType(std::string_view name);
inline size_t voxelTypeBytes(VoxelType type) {
  return type == VoxelType::kUint8 ? 1 : type == VoxelType::kUint16 ? 2 : 4;
}
/// The largest label an element of `type` holds.
inline uint32_t voxelTypeMax(VoxelType type) {
  return type == VoxelType::kUint8 ? 0xFFu : type == VoxelType::kUint16 ? 0xFFFFu : 0xFFFFFFFFu;
}

class LabelVolume {
 public:
  LabelVolume() = default;
  /// Throws std::invalid_argument when `bytes` does not hold dims.x * dims.y * dims.z elements of `type`.
  LabelVolume(const Coord& dims, VoxelType type, std::shared_ptr<const std::vector<uint8_t>> bytes);
  static Status make(const Coord& dims, VoxelType type, std::shared_ptr<const std::vector<uint8_t>> bytes,
                     LabelVolume* out);
  /// A uint8 volume (a seed mask) taking `mask` over; throws like the constructor.
  static LabelVolume ofMask(const Coord& dims, std::vector<uint8_t> mask) {
    return LabelVolume(dims, VoxelType::kUint8, std::make_shared<const std::vector<uint8_t>>(std::move(mask)));
  }

  const Coord& dims() const { return dims_; }
  VoxelType type() const { return type_; }
  int64_t voxelCount() const { return int64_t(dims_.x) * dims_.y * dims_.z; }
  size_t elementBytes() const { return voxelTypeBytes(type_); }
  const std::vector<uint8_t>& bytes() const { return *bytes_; }
  const std::shared_ptr<const std::vector<uint8_t>>& storage() const { return bytes_; }
  explicit operator bool() const { return bytes_ != nullptr; }
  /// The seed mask (1 where the label is nonzero), x fastest: a uint8 volume's own bytes, shared; a wider one's copy.
  std::shared_ptr<const std::vector<uint8_t>> seedMask() const;

  /// The label of voxel `i` (linear, x fastest).
  uint32_t at(int64_t i) const {
    const uint8_t* p = bytes_->data();
    switch (type_) {
      case VoxelType::kUint8: return p[i];
      case VoxelType::kUint16: {
        uint16_t v;
        std::memcpy(&v, p + 2 * i, 2);
        return v;
      }
      case VoxelType::kUint32: break;
    }
    uint32_t v;
    std::memcpy(&v, p + 4 * i, 4);
    return v;
  }

  /// f(const T* elements) with T = uint8_t, uint16_t or uint32_t as type() says; returns what f returns.
  template <class F>
  decltype(auto) visit(F&& f) const {
    switch (type_) {
      case VoxelType::kUint16: return f(reinterpret_cast<const uint16_t*>(bytes_->data()));
      case VoxelType::kUint32: return f(reinterpret_cast<const uint32_t*>(bytes_->data()));
      case VoxelType::kUint8: break;
    }
    return f(bytes_->data());
  }

 private:
  Coord dims_{};
  VoxelType type_ = VoxelType::kUint8;
  std::shared_ptr<const std::vector<uint8_t>> bytes_;
};

/// Whether the volume holds a nonzero voxel (want_zero = false) or a zero one (true): a pass over the elements, 8 bytes
/// a step, in parallel on the caller's TBB arena, stopping once found.
bool volumeHas(const LabelVolume& volume, bool want_zero);

/// Whether the volume holds at least two different labels (a voxel of another label exists for every voxel).
bool volumeHasTwoLabels(const LabelVolume& volume);

}  // namespace distband
