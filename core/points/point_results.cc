#include "core/points/point_results.h"

#include <bit>
#include <cstring>

namespace distband {

static_assert(std::endian::native == std::endian::little, "packed results are little-endian, as the host");

void PointResultBuffer::resize(size_t n, const PointOutputs& outputs) {
  outputs_ = outputs;
  distance_.resize(n);
  closest_.resize(outputs.closest_points ? n : 0);
  feature_.resize(outputs.features ? n : 0);
  gradient_.resize(outputs.gradients ? n : 0);
}

PointResults PointResultBuffer::results() {
  return {distance_.data(), outputs_.closest_points ? closest_.data() : nullptr,
          outputs_.features ? feature_.data() : nullptr, outputs_.gradients ? gradient_.data() : nullptr};
}

void PointResultBuffer::packValues(const double* values, size_t n, const PointPacking& p, std::string* out) {
  out->resize(n * (p.doubles ? 8 : 4));
  if (p.doubles) {
    if (n) std::memcpy(out->data(), values, n * 8);  // an empty output's data() may be null
    return;
  }
  char* dst = out->data();
  for (size_t i = 0; i < n; ++i) {
    const float f = float(values[i]);
    std::memcpy(dst + 4 * i, &f, 4);
  }
}

void PointResultBuffer::packClosestPoints(const PointPacking& p, std::string* out) const {
  static_assert(sizeof(Vec3d) == 3 * sizeof(double));
  packValues(reinterpret_cast<const double*>(closest_.data()), 3 * closest_.size(), p, out);
}

void PointResultBuffer::packGradients(const PointPacking& p, std::string* out) const {
  packValues(reinterpret_cast<const double*>(gradient_.data()), 3 * gradient_.size(), p, out);
}

void PointResultBuffer::packFeatures(const PointPacking& p, std::string* out) const {
  const size_t n = feature_.size();
  out->resize(n * (p.wide_ids ? 8 : 4));
  if (p.wide_ids) {
    if (n) std::memcpy(out->data(), feature_.data(), n * 8);
    return;
  }
  char* dst = out->data();
  for (size_t i = 0; i < n; ++i) {
    const int32_t id = int32_t(feature_[i]);
    std::memcpy(dst + 4 * i, &id, 4);
  }
}

}  // namespace distband
