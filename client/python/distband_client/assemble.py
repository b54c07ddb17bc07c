"""Assembles streamed bricks into dense (Z, Y, X) arrays, filled exactly as the CLI's .npy (client/brick_sink.cc).

* Voxels never delivered hold float32(header.limit) (+inf without a limit): the OpenVDB background.
* In a signed field an undelivered voxel takes the sign of the nearest delivered voxel before it in its x row
  (the first delivered voxel of the row when none precedes it); rows with no delivered voxel stay positive. The
  band encloses the surface, so a row enters and leaves the inside through delivered voxels.
* The closest-feature array holds -1 where nothing was delivered.
Each batch is decoded with whole-array numpy operations (no per-voxel Python loop).
"""
import numpy as np

from .errors import DistbandError
from .stubs import pb

_BRICK = 8


def _protocol(message):
    return DistbandError("PROTOCOL", message)


def _local_index(Y, X):
    """Flat (Z, Y, X) index of each brick offset (lx << 6) | (ly << 3) | lz relative to the brick's origin."""
    offset = np.arange(512)
    return ((offset & 7) * Y + ((offset >> 3) & 7)) * X + (offset >> 6)


class FieldAssembler:
    def __init__(self, header, want_closest):
        d = header.dims
        if not (d.x >= 1 and d.y >= 1 and d.z >= 1):
            raise _protocol(f"the header's dims ({d.x}, {d.y}, {d.z}) are empty")
        self.shape = (d.z, d.y, d.x)
        self.value_dtype = np.dtype("<f2" if header.encoding == pb.BRICK_ENCODING_FLOAT16 else "<f4")
        self.field = np.full(self.shape, np.float32(header.limit), dtype=np.float32)
        self.signed = header.signed
        self.delivered = np.zeros(self.shape, dtype=bool) if self.signed else None
        self.closest = None
        self.closest_dtype = None
        if want_closest:
            if header.closest_feature in (pb.CLOSEST_FEATURE_TRIANGLE, pb.CLOSEST_FEATURE_POINT):
                self.closest_dtype = np.dtype("<i4")
            elif header.closest_feature == pb.CLOSEST_FEATURE_VOXEL:
                self.closest_dtype = np.dtype("<i8")
            elif header.closest_feature == pb.CLOSEST_FEATURE_LABEL:
                self.closest_dtype = np.dtype("<u4")  # nearest labels, held as int64 (-1: not delivered)
            else:
                raise DistbandError(
                    "UNIMPLEMENTED", "closest=True, but the server's header reports no closest feature "
                    f"(QueryHeader.closest_feature = {header.closest_feature}): the server predates closest features")
            held = np.dtype(np.int64) if self.closest_dtype.kind == "u" else self.closest_dtype.newbyteorder("=")
            self.closest = np.full(self.shape, -1, dtype=held)

    def add(self, batch):
        """Places one BrickBatch; returns the number of voxels it delivered."""
        bricks = batch.bricks
        n = len(bricks)
        if n == 0:
            return 0
        masks = b"".join(b.mask for b in bricks)
        if len(masks) != 64 * n or any(len(b.mask) != 64 for b in bricks):
            raise _protocol("a brick mask does not have 64 bytes")
        origins = np.array([(b.x, b.y, b.z) for b in bricks], dtype=np.int64)
        if (origins % _BRICK).any():
            raise _protocol("a brick origin is not a multiple of 8")
        bits = np.unpackbits(np.frombuffer(masks, np.uint8).reshape(n, 64), axis=1, bitorder="little").astype(bool)
        counts = bits.sum(axis=1)
        value_bytes = np.array([len(b.values) for b in bricks], dtype=np.int64)
        if (value_bytes != counts * self.value_dtype.itemsize).any():
            raise _protocol("a brick's values do not match its mask's voxel count")
        values = np.frombuffer(b"".join(b.values for b in bricks), self.value_dtype).astype(np.float32)
        brick, offset = np.nonzero(bits)  # brick-major, offsets increasing: the order of `values`
        Z, Y, X = self.shape
        # Flat (Z, Y, X) index = the brick origin's + the local voxel's: two gathers instead of three coordinates.
        index = ((origins[:, 2] * Y + origins[:, 1]) * X + origins[:, 0])[brick] + _local_index(Y, X)[offset]
        # The protocol never marks voxels outside the grid; like the CLI, ignore any that are (only bricks on the
        # far faces or with bad origins can hold some, so the others skip the per-voxel test).
        partial = (origins < 0).any(axis=1) | (origins + _BRICK > np.array([X, Y, Z])).any(axis=1)
        if partial.any():
            x = origins[brick, 0] + (offset >> 6)
            y = origins[brick, 1] + ((offset >> 3) & 7)
            z = origins[brick, 2] + (offset & 7)
            inside = (x >= 0) & (y >= 0) & (z >= 0) & (x < X) & (y < Y) & (z < Z)
            index, values = index[inside], values[inside]
        else:
            inside = slice(None)
        self.field.reshape(-1)[index] = values
        if self.delivered is not None:
            self.delivered.reshape(-1)[index] = True
        if self.closest is not None:
            closest_bytes = np.array([len(b.closest) for b in bricks], dtype=np.int64)
            if (closest_bytes != counts * self.closest_dtype.itemsize).any():
                raise _protocol("a brick's closest features do not match its mask's voxel count")
            ids = np.frombuffer(b"".join(b.closest for b in bricks), self.closest_dtype)
            self.closest.reshape(-1)[index] = ids[inside]
        return int(brick.size)

    def finish(self):
        """The field (and the closest-feature array, or None) once the stream has ended."""
        if self.signed:
            self._fill_signs_along_rows()
        return self.field, self.closest

    def _fill_signs_along_rows(self):
        delivered, field = self.delivered, self.field
        X = self.shape[2]
        rows = delivered.any(axis=2)  # rows without a delivered voxel stay positive
        d, v = delivered[rows], field[rows]  # (rows, X) copies of just the rows that need work
        columns = np.arange(X, dtype=np.int16)  # X <= 16384
        # For each voxel, the x of the nearest delivered voxel at or before it in its row, else the row's first.
        before = np.maximum.accumulate(np.where(d, columns, np.int16(-1)), axis=1)
        source = np.where(before >= 0, before, np.argmax(d, axis=1).astype(np.int16)[:, None])
        row_start = np.arange(d.shape[0], dtype=np.int64)[:, None] * X
        negative = (v < 0).reshape(-1)[row_start + source]
        fill = ~d
        v[fill] = np.where(negative[fill], -np.abs(v[fill]), np.abs(v[fill]))
        field[rows] = v
