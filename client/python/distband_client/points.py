"""distance_at(): the distance field at arbitrary points, through the server's QueryPoints stream.

The query points travel in chunks (at most the server's max_chunk_points, 65536) from a generator that gRPC reads as
flow control allows, and the results come back chunk by chunk in order; they are checked (chunk index, first point,
count) and assembled into numpy arrays in the points' order.
"""
import grpc
import numpy as np

from .errors import DistbandError
from .query import _channel, _check_connection_args
from .request import _SIGNS, _choice, _number, _points, _read_mesh, _triple, _volume
from .stubs import pb, rpc

_MAX_CHUNK_POINTS = 65536


def _query_points(at):
    if isinstance(at, (str, bytes)):
        raise TypeError("at must be an (N, 3) array of query points")
    try:
        arr = np.asarray(at)
    except (TypeError, ValueError):
        raise TypeError("at must be an (N, 3) array of query points") from None
    if arr.dtype != np.float32:
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"at must hold numbers (got dtype {arr.dtype})") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"at must have shape (N, 3) (got {arr.shape})")
    if arr.shape[0] == 0:
        raise ValueError("at must hold at least one point")
    bad = np.nonzero(~np.isfinite(arr).all(axis=1))[0]
    if bad.size:
        raise ValueError(f"at[{bad[0]}] must have finite coordinates (got {tuple(arr[bad[0]].tolist())})")
    return np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))


def distance_at(server, at, *, mesh=None, points=None, volume=None, volume_origin=None, volume_voxel_size=None,
                sign=None, limit=None, closest_points=False, ids=False, gradient=False, chunk_points=16384,
                token=None, root_certificates=None, timeout=None):
    """The signed distance at each of the query points ``at`` ((N, 3) array), computed by a distband server.

    Seeds as in query(): exactly one of ``mesh`` (a file path), ``points`` ((x, y, z) world coordinates) or
    ``volume`` (bool/uint8 (Z, Y, X); its voxels at ``volume_origin`` + ``volume_voxel_size`` * (x, y, z), default
    origin 0 and size 1). ``sign`` and ``limit`` as in query() (``limit``: points farther get +-limit, id -1, closest
    point NaN, gradient 0). Values come back in the points' type (float32 for a float32 array, else float64).
    Returns the distances (N,), or with ``closest_points``, ``ids`` or ``gradient`` a dict with "distance" and each
    output asked for: "closest_points" (N, 3), "ids" (N,) int32 (triangle, point) or int64 (voxel), "gradient" (N, 3)
    unit vectors. ValueError/TypeError for bad arguments before connecting; DistbandError for what the server reports.
    """
    arr = _query_points(at)
    given = [name for name, v in (("mesh", mesh), ("points", points), ("volume", volume)) if v is not None]
    if len(given) != 1:
        raise ValueError("give exactly one seed source: mesh, points or volume")
    if (volume_origin is not None or volume_voxel_size is not None) and volume is None:
        raise ValueError("volume_origin and volume_voxel_size place a volume's voxels; give them with volume only")
    if isinstance(chunk_points, bool) or not isinstance(chunk_points, int) or not 1 <= chunk_points <= _MAX_CHUNK_POINTS:
        raise ValueError(f"chunk_points must be an integer in [1, {_MAX_CHUNK_POINTS}] (got {chunk_points!r})")
    _check_connection_args(token, root_certificates, timeout, None)
    header = pb.PointsHeader()
    if mesh is not None:
        header.mesh.CopyFrom(_read_mesh(mesh))
    elif points is not None:
        header.points.CopyFrom(_points(points))
    else:
        header.volume.CopyFrom(_volume(volume))
        if volume_origin is not None:
            x, y, z = _triple("volume_origin", volume_origin, lambda n, v: _number(n, v))
            header.volume_origin.CopyFrom(pb.Vec3(x=x, y=y, z=z))
        if volume_voxel_size is not None:
            header.volume_voxel_size = _number("volume_voxel_size", volume_voxel_size, positive=True)
    s = _choice("sign", sign, _SIGNS)
    if s is not None:
        header.sign = s
    lim = _number("limit", limit, positive=True, allow_inf=True)
    if lim is not None:
        header.limit = lim
    doubles = arr.dtype == np.float64
    header.coordinates = pb.VALUE_TYPE_FLOAT64 if doubles else pb.VALUE_TYPE_FLOAT32
    header.closest_points = bool(closest_points)
    header.closest_feature = bool(ids)
    header.gradient = bool(gradient)
    metadata = [("authorization", f"Bearer {token}")] if token is not None else None

    n = arr.shape[0]

    def requests():
        yield pb.PointsRequest(header=header)
        for i in range(0, n, chunk_points):
            yield pb.PointsRequest(chunk=pb.PointsChunk(xyz=arr[i:i + chunk_points].tobytes()))

    value = np.dtype("<f8" if doubles else "<f4")
    out = {"distance": np.empty(n, value)}
    if closest_points:
        out["closest_points"] = np.empty((n, 3), value)
    if gradient:
        out["gradient"] = np.empty((n, 3), value)
    with _channel(server, root_certificates) as channel:
        call = rpc.DistanceFieldStub(channel).QueryPoints(requests(), metadata=metadata, timeout=timeout)
        try:
            got_header = summary = None
            done = chunk = 0
            for reply in call:
                kind = reply.WhichOneof("kind")
                if kind == "header":
                    if got_header is not None:
                        raise DistbandError("PROTOCOL", "a second header arrived")
                    got_header = reply.header
                    if ids:
                        wide = got_header.closest_feature == pb.CLOSEST_FEATURE_VOXEL
                        out["ids"] = np.empty(n, np.dtype("<i8" if wide else "<i4"))
                elif got_header is None or summary is not None:
                    raise DistbandError("PROTOCOL", f"a '{kind}' message arrived out of order")
                elif kind == "results":
                    r = reply.results
                    k = r.points
                    if r.chunk != chunk or r.first_point != done or k != min(chunk_points, n - done):
                        raise DistbandError("PROTOCOL", f"results of chunk {r.chunk} (first point {r.first_point}, "
                                            f"{k} points) arrived where chunk {chunk} was due")
                    out["distance"][done:done + k] = np.frombuffer(r.distance, value, k)
                    if closest_points:
                        out["closest_points"][done:done + k] = np.frombuffer(r.closest_points, value, 3 * k).reshape(k, 3)
                    if gradient:
                        out["gradient"][done:done + k] = np.frombuffer(r.gradient, value, 3 * k).reshape(k, 3)
                    if ids:
                        out["ids"][done:done + k] = np.frombuffer(r.closest_feature, out["ids"].dtype, k)
                    done += k
                    chunk += 1
                elif kind == "summary":
                    summary = reply.summary
                else:
                    raise DistbandError("PROTOCOL", "a reply with no content arrived")
            if summary is None or done != n:
                raise DistbandError("PROTOCOL", f"the stream ended after {done} of {n} points without a summary"
                                    if summary is None else f"the summary came after {done} of {n} points")
        except grpc.RpcError as e:
            raise DistbandError(e.code().name, e.details()) from None
        except ValueError as e:  # a short buffer from the server
            raise DistbandError("PROTOCOL", str(e)) from None
        finally:
            call.cancel()
    if not (closest_points or ids or gradient):
        return out["distance"]
    return out

