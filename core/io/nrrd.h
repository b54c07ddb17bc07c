// NRRD: seed and label volumes in the Nearly Raw Raster Data format (.nrrd with attached data, .nhdr with a data
// file), read in memory with the untrusted-input rules of core/io/volume_file.h.
// Contract of parseNrrd():
//   * The header: magic NRRD0001..NRRD0005, then "field: value" lines (comments "#" and "key:=value" pairs skipped)
//     up to an empty line; at most 64 KiB of header and 1 KiB a line. Required: type (unsigned, signed or floating
//     names of 8 to 64 bits, converted as volume_file.h says), dimension 3, sizes (each in [1, kMaxGridDim], their
//     product within limits.max_voxels), encoding raw or gzip; endian little or big (little when absent). The
//     geometry: space directions (axis-aligned, with a 3-D space) and space origin, else spacings, else 1s.
//     Unknown fields are ignored; a field given twice, byte or line skips, and other encodings are refused.
//   * The data: attached (after the header's empty line), or in the detached file the header's "data file" names,
//     which only `detached` provides (null: refused — the service never opens a file a header names). Raw data must
//     be exactly the declared bytes; gzip data inflate to exactly them (bounded: see core/io/gzip.h).
//   * Returns kInvalidArgument (kResourceExhausted beyond the limits) naming `name`. Pure; thread-safe.
#pragma once

#include <functional>
#include <string>
#include <string_view>

#include "core/io/volume_file.h"
#include "core/status.h"

namespace distband {

/// Reads a detached data file named by a header, at most `max_bytes` of it (kResourceExhausted beyond).
using NrrdDataFile = std::function<Status(const std::string& file, uint64_t max_bytes, std::string* data)>;

Status parseNrrd(std::string_view bytes, std::string_view name, const VolumeReadLimits& limits,
                 const NrrdDataFile* detached, VolumeImage* out);

}  // namespace distband
