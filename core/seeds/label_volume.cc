#include "core/seeds/label_volume.h"

#include <algorithm>
#include <atomic>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace distband {

std::string_view voxelTypeName(VoxelType type) {
  switch (type) {
    case VoxelType::kUint8: return "uint8";
    case VoxelType::kUint16: return "uint16";
    case VoxelType::kUint32: return "uint32";
  }
  return "?";
}

std::optional<VoxelType> parseVoxelType(std::string_view name) {
  for (VoxelType t : kVoxelTypes)
    if (name == voxelTypeName(t)) return t;
  return std::nullopt;
}

Status LabelVolume::make(const Coord& dims, VoxelType type, std::shared_ptr<const std::vector<uint8_t>> bytes,
                         LabelVolume* out) {
  if (!bytes) return Status::InvalidArgument("the volume has no data");
  const int64_t voxels = int64_t(dims.x) * dims.y * dims.z;
  if (dims.x < 1 || dims.y < 1 || dims.z < 1 || bytes->size() != uint64_t(voxels) * voxelTypeBytes(type))
    return Status::InvalidArgument(fmt::format("the volume has {} bytes, dims {}x{}x{} of {} need {}", bytes->size(),
                                               dims.x, dims.y, dims.z, voxelTypeName(type),
                                               uint64_t(std::max<int64_t>(voxels, 0)) * voxelTypeBytes(type)));
  out->dims_ = dims;
  out->type_ = type;
  out->bytes_ = std::move(bytes);
  return Status::Ok();
}

std::shared_ptr<const std::vector<uint8_t>> LabelVolume::seedMask() const {
  if (type_ == VoxelType::kUint8) return bytes_;
  auto mask = std::make_shared<std::vector<uint8_t>>(size_t(voxelCount()));
  for (int64_t i = 0; i < voxelCount(); ++i) (*mask)[size_t(i)] = at(i) != 0;
  return mask;
}

LabelVolume::LabelVolume(const Coord& dims, VoxelType type, std::shared_ptr<const std::vector<uint8_t>> bytes) {
  if (Status s = make(dims, type, std::move(bytes), this); !s.ok()) throw std::invalid_argument(s.message());
}

namespace {

// A parallel search over slices of `count` elements, every slice stopping once one found it (one element at a time on
// one thread, a whole-grid field's 128 MiB would be 0.5 % of a 1-thread run, a serial part that 16 threads would not
// share).
template <class Hit>
bool anySlice(size_t count, const Hit& hit) {
  constexpr size_t kSlice = size_t(1) << 20;
  std::atomic<bool> found{false};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, (count + kSlice - 1) / kSlice, 1),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t s = r.begin(); s != r.end() && !found.load(std::memory_order_relaxed); ++s)
                        if (hit(s * kSlice, std::min(count, (s + 1) * kSlice))) found.store(true, std::memory_order_relaxed);
                    });
  return found.load();
}

}  // namespace

bool volumeHas(const LabelVolume& volume, bool want_zero) {
  const std::vector<uint8_t>& bytes = volume.bytes();
  if (!want_zero || volume.type() == VoxelType::kUint8)
    // A nonzero element is a nonzero byte whatever the width; a zero uint8 a zero byte: 8 bytes a step.
    return anySlice(bytes.size(), [&](size_t begin, size_t end) {
      const uint8_t* p = bytes.data();
      size_t i = begin;
      for (; i + 8 <= end; i += 8) {
        uint64_t w;
        std::memcpy(&w, p + i, 8);
        // A zero byte: the classic (w - 0x01..) & ~w & 0x80.. test.
        if (want_zero ? ((w - 0x0101010101010101ull) & ~w & 0x8080808080808080ull) != 0 : w != 0) return true;
      }
      for (; i < end; ++i)
        if ((p[i] == 0) == want_zero) return true;
      return false;
    });
  return volume.visit([&](const auto* labels) {
    return anySlice(size_t(volume.voxelCount()), [&](size_t begin, size_t end) {
      return std::find(labels + begin, labels + end, 0) != labels + end;
    });
  });
}

bool volumeHasTwoLabels(const LabelVolume& volume) {
  const uint32_t first = volume.at(0);
  return volume.visit([&](const auto* labels) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(labels)>>;
    return anySlice(size_t(volume.voxelCount()), [&](size_t begin, size_t end) {
      return std::find_if(labels + begin, labels + end, [&](T v) { return v != T(first); }) != labels + end;
    });
  });
}

}  // namespace distband
