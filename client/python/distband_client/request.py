"""Checks query() arguments and turns them into a distband.v1 QueryRequest.

Everything the client can judge on its own (types, signs, which arguments go together, the mesh file) is checked
here, before any connection, and reported as ValueError/TypeError naming the argument. Rules that depend on the
server (voxel budget, upper bounds, mesh contents) are left to it: its INVALID_ARGUMENT messages name the field.
"""
import math
import numbers
import os

import numpy as np

from .stubs import pb

_MESH_FORMATS = {".obj": pb.MESH_FORMAT_OBJ, ".off": pb.MESH_FORMAT_OFF, ".ply": pb.MESH_FORMAT_PLY,
                 ".stl": pb.MESH_FORMAT_STL}
# The CLI's spellings (distband query --stencil/--mode/--sign/--encoding), so both read alike.
_STENCILS = {"auto": pb.STENCIL_UNSPECIFIED, "cubic6": pb.STENCIL_CUBIC6, "cubic18": pb.STENCIL_CUBIC18,
             "cubic26": pb.STENCIL_CUBIC26, "fcc12": pb.STENCIL_FCC12}
_MODES = {"exact": pb.PROPAGATION_MODE_EXACT, "exact-feature": pb.PROPAGATION_MODE_EXACT,
          "paper": pb.PROPAGATION_MODE_PAPER}
_SIGNS = {"auto": pb.SIGN_MODE_AUTO, "unsigned": pb.SIGN_MODE_UNSIGNED, "pseudonormal": pb.SIGN_MODE_PSEUDONORMAL,
          "winding": pb.SIGN_MODE_WINDING, "parity": pb.SIGN_MODE_PARITY, "mask-inside": pb.SIGN_MODE_MASK_INSIDE}
_ENCODINGS = {"float32": pb.BRICK_ENCODING_FLOAT32, "float16": pb.BRICK_ENCODING_FLOAT16}


def _choice(name, value, table):
    if value is None:
        return None
    if not isinstance(value, str) or value not in table:
        raise ValueError(f"{name}={value!r}: expected one of {', '.join(repr(k) for k in table)}")
    return table[value]


def _number(name, value, *, positive=False, nonnegative=False, allow_inf=False):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number (got {type(value).__name__})")
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{name} must be finite (got {value!r})")
    if positive and not v > 0:
        raise ValueError(f"{name} must be > 0 (got {value!r})")
    if nonnegative and not v >= 0:
        raise ValueError(f"{name} must be >= 0 (got {value!r})")
    return v


def _integer(name, value, *, minimum):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer (got {type(value).__name__})")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum} (got {value})")
    return int(value)


def _triple(name, value, convert):
    try:
        items = list(value)
    except TypeError:
        raise TypeError(f"{name} must be a sequence of 3 numbers (x, y, z)") from None
    if len(items) != 3:
        raise ValueError(f"{name} must have 3 components (x, y, z), got {len(items)}")
    return [convert(f"{name}[{i}]", v) for i, v in enumerate(items)]


def _read_mesh(mesh):
    if not isinstance(mesh, (str, os.PathLike)):
        raise TypeError(f"mesh must be a path to an .obj, .off, .ply or .stl file (got {type(mesh).__name__})")
    path = os.fspath(mesh)
    fmt = _MESH_FORMATS.get(os.path.splitext(path)[1].lower())
    if fmt is None:
        raise ValueError(f"mesh={path!r}: unsupported mesh format (expected .obj, .off, .ply or .stl)")
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise ValueError(f"mesh={path!r}: cannot read the file ({e.strerror})") from None
    return pb.InlineMesh(format=fmt, data=data)


def _points(points):
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError("points must be a sequence of (x, y, z) world coordinates") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3) (got {arr.shape})")
    if arr.shape[0] == 0:
        raise ValueError("points must hold at least one point")
    bad = np.nonzero(~np.isfinite(arr).all(axis=1))[0]
    if bad.size:
        raise ValueError(f"points[{bad[0]}] must have finite coordinates (got {tuple(arr[bad[0]])})")
    return pb.PointList(points=[pb.Vec3(x=x, y=y, z=z) for x, y, z in arr.tolist()])


_VOXEL_TYPES = {np.dtype(np.bool_): pb.VOXEL_TYPE_UINT8, np.dtype(np.uint8): pb.VOXEL_TYPE_UINT8,
                np.dtype(np.uint16): pb.VOXEL_TYPE_UINT16, np.dtype(np.uint32): pb.VOXEL_TYPE_UINT32}


def _volume(volume):
    if not isinstance(volume, np.ndarray):
        raise TypeError(f"volume must be a numpy array of bool, uint8, uint16 or uint32 (got {type(volume).__name__})")
    if volume.dtype not in _VOXEL_TYPES:
        raise TypeError(f"volume must have dtype bool, uint8, uint16 or uint32 (got {volume.dtype})")
    if volume.ndim != 3:
        raise ValueError(f"volume must be 3-D, shape (Z, Y, X) (got shape {volume.shape})")
    z, y, x = volume.shape
    # The wire mask is x fastest = C order of a (Z, Y, X) array, little-endian elements.
    data = np.ascontiguousarray(volume).view(np.uint8) if volume.dtype == np.bool_ else \
        np.ascontiguousarray(volume, dtype=volume.dtype.newbyteorder("<"))
    return pb.InlineVolume(dims=pb.Dims(x=x, y=y, z=z), mask=data.tobytes(), element_type=_VOXEL_TYPES[volume.dtype])


def build_request(*, mesh, points, volume, resolution, voxel_size, dims, origin, padding, limit, limit_voxels,
                  sign, mode, stencil, segment_length, encoding, closest, spacing=None, labels=False,
                  black_border=False, nearest_label=False):
    """The QueryRequest for query()'s arguments; raises ValueError/TypeError naming the first bad argument."""
    given = [name for name, v in (("mesh", mesh), ("points", points), ("volume", volume)) if v is not None]
    if len(given) != 1:
        raise ValueError("give exactly one seed source: mesh=, points= or volume= "
                         + (f"(got {' and '.join(given)})" if given else "(got none)"))

    resolution = _integer("resolution", resolution, minimum=2)
    voxel_size = _number("voxel_size", voxel_size, positive=True)
    padding = _integer("padding", padding, minimum=0)
    grid_dims = None if dims is None else _triple("dims", dims, lambda n, v: _integer(n, v, minimum=1))
    grid_origin = None if origin is None else _triple("origin", origin, _number)
    # spacing: in the array's axis order (Z, Y, X), as scipy's `sampling`; the wire's is (x, y, z).
    grid_spacing = None if spacing is None else _triple("spacing", spacing,
                                                         lambda n, v: _number(n, v, positive=True))[::-1]
    if grid_spacing is not None and voxel_size is not None:
        raise ValueError("spacing and voxel_size are exclusive (voxel_size v means spacing (v, v, v))")
    if grid_spacing is not None and grid_dims is None and volume is None:
        raise ValueError("spacing applies to dims or a volume (around the seeds give voxel_size or resolution)")
    for name, flag in (("labels", labels), ("black_border", black_border), ("nearest_label", nearest_label)):
        if not isinstance(flag, bool):
            raise TypeError(f"{name} must be True or False (got {type(flag).__name__})")
        if flag and volume is None:
            raise ValueError(f"{name} applies to volume seeds (volume=)")
    if black_border and not labels:
        raise ValueError("black_border applies with labels=True (the multi-label EDT)")
    if nearest_label and (labels or closest):
        raise ValueError("nearest_label excludes labels and closest (one closest feature per voxel)")
    # The three ways of GridSpec (see the proto): explicit dims (volumes imply them), or a box grown by padding
    # around the seeds, sized by exactly one of resolution and voxel_size.
    if grid_dims is not None or volume is not None:
        if resolution is not None:
            raise ValueError("resolution cannot be combined with dims or a volume (give voxel_size)")
        if padding is not None:
            raise ValueError("padding cannot be combined with dims or a volume")
        if volume is None and voxel_size is None and spacing is None:
            raise ValueError("dims needs voxel_size or spacing")
    else:
        if origin is not None:
            raise ValueError("origin is only used with dims or a volume (otherwise the seeds' bounds give it)")
        if (resolution is None) == (voxel_size is None):
            raise ValueError("give exactly one of resolution and voxel_size (or dims with voxel_size)")

    limit = _number("limit", limit, positive=True, allow_inf=True)
    limit_voxels = _number("limit_voxels", limit_voxels, positive=True)
    if limit is not None and limit_voxels is not None:
        raise ValueError("limit and limit_voxels are exclusive: give the distance limit in world units or in voxels")
    segment_length = _number("segment_length", segment_length, nonnegative=True)
    if not isinstance(closest, bool):
        raise TypeError(f"closest must be True or False (got {type(closest).__name__})")

    request = pb.QueryRequest()
    if mesh is not None:
        request.mesh.CopyFrom(_read_mesh(mesh))
    elif points is not None:
        request.points.CopyFrom(_points(points))
    else:
        request.volume.CopyFrom(_volume(volume))
    g = request.grid
    g.SetInParent()  # present even when empty: a volume's grid defaults to its own dims and voxel size 1
    if resolution is not None:
        g.resolution = resolution
    if voxel_size is not None:
        g.voxel_size = voxel_size
    if padding is not None:
        g.padding = padding
    if grid_dims is not None:
        g.dims.CopyFrom(pb.Dims(x=grid_dims[0], y=grid_dims[1], z=grid_dims[2]))
    if grid_origin is not None:
        g.origin.CopyFrom(pb.Vec3(x=grid_origin[0], y=grid_origin[1], z=grid_origin[2]))
    if grid_spacing is not None:
        g.spacing.CopyFrom(pb.Vec3(x=grid_spacing[0], y=grid_spacing[1], z=grid_spacing[2]))
    for field, value in (("stencil", _choice("stencil", stencil, _STENCILS)),
                         ("mode", _choice("mode", mode, _MODES)),
                         ("sign", _choice("sign", sign, _SIGNS)),
                         ("encoding", _choice("encoding", encoding, _ENCODINGS)),
                         ("limit", limit), ("limit_voxels", limit_voxels), ("segment_length", segment_length)):
        if value is not None:
            setattr(request, field, value)
    request.closest_feature = closest
    request.labels = labels
    request.black_border = black_border
    request.nearest_label = nearest_label
    return request
