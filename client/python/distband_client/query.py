"""query() and query_result(): one distband.v1 Query call, its stream assembled into numpy arrays."""
import dataclasses
import math
import numbers

import grpc

from .assemble import FieldAssembler
from .errors import DistbandError
from .request import build_request
from .stubs import pb, rpc

# The server bounds what it sends by its own --max-message-bytes; the client must not refuse what it sends.
_CHANNEL_OPTIONS = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]


def _enum_name(enum, value, prefix):
    """'pseudonormal' for SIGN_MODE_PSEUDONORMAL: the CLI's spelling; the number for a value newer than this client."""
    try:
        return enum.Name(value)[len(prefix):].lower().replace("_", "-")
    except ValueError:
        return str(value)


@dataclasses.dataclass(frozen=True)
class Header:
    """The grid and settings the server used (QueryHeader). Voxel (i, j, k) = field[k, j, i] sits at world
    position origin + spacing * (i, j, k), axis by axis."""
    origin: tuple           # (x, y, z) world position of voxel (0, 0, 0)
    voxel_size: float       # world units per voxel (the smallest spacing on an anisotropic grid)
    dims: tuple             # (x, y, z) voxels
    shape: tuple            # (Z, Y, X): the returned arrays' shape
    limit: float            # distance limit in world units (+inf without one); undelivered voxels hold +-limit
    signed: bool            # whether values can be negative (negative inside)
    sign: str               # sign mode in force: 'unsigned', 'pseudonormal', 'winding', 'parity', 'mask-inside', ...
    sign_reason: str        # why that sign mode (SIGN_MODE_AUTO), '' if the server gives none
    padding: int            # voxels of margin around the seeds' bounds (0 with explicit dims)
    band_clipped: bool      # the grid's faces cut voxels within the limit
    stencil: str
    mode: str
    encoding: str           # 'float32' or 'float16' (values are returned as float32 either way)
    segment_length: float
    closest_feature: str    # 'none', 'triangle', 'point', 'voxel' or 'label'
    expected_voxels: int    # the server's estimate of the voxels it will deliver; 0 = unknown
    query_id: str
    # How the field was computed (QueryHeader.algorithm; core's algorithmDescription says the same): "band", the
    # adaptive iteration on an evolving active band (SMI 2009; any seeds), whose segments stream nearest first as the
    # band passes them; or "separable", an exact EDT axis by axis (exact mode, no stencil or second ring asked for):
    # over the whole grid for a seed volume without a limit and for point seeds on few lattice planes without a limit,
    # over the bricks within the limit of the boundary for a limited seed volume; a volume's first segment comes
    # first, from the bricks within its bound (several segments; no limit or one of many bricks), the points' once
    # the whole field is known.
    algorithm: str
    spacing: tuple = ()     # (x, y, z) voxel size per axis (the wire's order; numpy's is reversed)
    labels: bool = False    # the multi-label EDT
    black_border: bool = False

    @classmethod
    def from_proto(cls, h):
        return cls(origin=(h.origin.x, h.origin.y, h.origin.z), voxel_size=h.voxel_size,
                   dims=(h.dims.x, h.dims.y, h.dims.z), shape=(h.dims.z, h.dims.y, h.dims.x), limit=h.limit,
                   signed=h.signed, sign=_enum_name(pb.SignMode, h.sign, "SIGN_MODE_"), sign_reason=h.sign_reason,
                   padding=h.padding, band_clipped=h.band_clipped,
                   stencil=_enum_name(pb.Stencil, h.stencil, "STENCIL_"),
                   mode=_enum_name(pb.PropagationMode, h.mode, "PROPAGATION_MODE_"),
                   encoding=_enum_name(pb.BrickEncoding, h.encoding, "BRICK_ENCODING_"),
                   segment_length=h.segment_length,
                   closest_feature=_enum_name(pb.ClosestFeature, h.closest_feature, "CLOSEST_FEATURE_"),
                   expected_voxels=h.expected_voxels, query_id=h.query_id, algorithm=h.algorithm,
                   spacing=(h.spacing.x, h.spacing.y, h.spacing.z) if h.HasField("spacing") else (h.voxel_size,) * 3,
                   labels=h.labels, black_border=h.black_border)


@dataclasses.dataclass
class Result:
    """Everything one query returned."""
    field: "numpy.ndarray"    # float32 (Z, Y, X), as the CLI's .npy
    closest: "numpy.ndarray"  # int32 (triangle, point) or int64 (voxel) (Z, Y, X), -1 where not delivered; None
                              # unless closest=True
    header: Header
    summary: "pb.QuerySummary"  # the server's totals and per-segment timings (the protobuf message)


def _check_connection_args(token, root_certificates, timeout, progress):
    if token is not None:
        if not isinstance(token, str) or not token:
            raise TypeError("token must be a non-empty string")
        if any(c.isspace() or not c.isprintable() for c in token):
            raise ValueError("token must be printable without spaces or newlines")  # never echo a token
    if root_certificates is not None and not isinstance(root_certificates, (bytes, str)):
        raise TypeError("root_certificates must be the PEM bytes of the CA certificates (e.g. open(ca, 'rb').read())")
    if timeout is not None and (isinstance(timeout, bool) or not isinstance(timeout, numbers.Real)
                                or not (timeout > 0 and math.isfinite(timeout))):
        raise ValueError(f"timeout must be a finite number of seconds > 0 (got {timeout!r})")
    if progress is not None and not callable(progress):
        raise TypeError("progress must be callable as progress(voxels_done, expected_voxels, segment)")


def _channel(server, root_certificates):
    if not isinstance(server, str) or not server:
        raise TypeError("server must be a gRPC target string such as '127.0.0.1:50051'")
    if root_certificates is None:
        return grpc.insecure_channel(server, options=_CHANNEL_OPTIONS)
    pem = root_certificates.encode() if isinstance(root_certificates, str) else root_certificates
    return grpc.secure_channel(server, grpc.ssl_channel_credentials(root_certificates=pem), options=_CHANNEL_OPTIONS)


def query_result(server, *, mesh=None, points=None, volume=None, resolution=None, voxel_size=None, dims=None,
                 origin=None, padding=None, limit=None, limit_voxels=None, sign=None, mode=None, stencil=None,
                 segment_length=None, encoding=None, closest=False, progress=None, token=None,
                 root_certificates=None, timeout=None, spacing=None, labels=False, black_border=False,
                 nearest_label=False):
    """Like query(), but returns a Result with the field, the closest features, the header and the summary."""
    request = build_request(mesh=mesh, points=points, volume=volume, resolution=resolution, voxel_size=voxel_size,
                            dims=dims, origin=origin, padding=padding, limit=limit, limit_voxels=limit_voxels,
                            sign=sign, mode=mode, stencil=stencil, segment_length=segment_length,
                            encoding=encoding, closest=closest, spacing=spacing, labels=labels,
                            black_border=black_border, nearest_label=nearest_label)
    _check_connection_args(token, root_certificates, timeout, progress)
    metadata = [("authorization", f"Bearer {token}")] if token is not None else None

    with _channel(server, root_certificates) as channel:
        call = rpc.DistanceFieldStub(channel).Query(request, metadata=metadata, timeout=timeout)
        try:
            return _read_stream(call, closest or nearest_label, progress)
        except grpc.RpcError as e:
            raise DistbandError(e.code().name, e.details()) from None
        finally:
            # A progress callback that raised, a protocol error or Ctrl-C: cancelling stops the server's engine.
            call.cancel()


def _read_stream(call, want_closest, progress):
    header = assembler = summary = None
    segment = 0
    voxels_done = 0
    for reply in call:
        kind = reply.WhichOneof("kind")
        if kind == "header":
            if header is not None:
                raise DistbandError("PROTOCOL", "a second header arrived")
            header = reply.header
            assembler = FieldAssembler(header, want_closest)
        elif header is None or summary is not None:
            raise DistbandError("PROTOCOL", f"a '{kind}' message arrived "
                                + ("before the header" if header is None else "after the summary"))
        elif kind == "bricks":
            if reply.bricks.segment != segment:
                raise DistbandError("PROTOCOL", f"bricks of segment {reply.bricks.segment} arrived while segment "
                                    f"{segment} was open")
            voxels_done += assembler.add(reply.bricks)
            if progress is not None:
                progress(voxels_done, header.expected_voxels, segment)
        elif kind == "segment_done":
            if reply.segment_done.segment != segment:
                raise DistbandError("PROTOCOL", f"segment_done for segment {reply.segment_done.segment} while "
                                    f"segment {segment} was open")
            segment += 1
        elif kind == "summary":
            summary = reply.summary
        else:
            raise DistbandError("PROTOCOL", "a reply with no content arrived")
    if summary is None:
        raise DistbandError("PROTOCOL", "the stream ended without a summary")
    field, closest = assembler.finish()
    return Result(field=field, closest=closest, header=Header.from_proto(header), summary=summary)


def query(server, *, mesh=None, points=None, volume=None, resolution=None, voxel_size=None, dims=None, origin=None,
          padding=None, limit=None, limit_voxels=None, sign=None, mode=None, stencil=None, segment_length=None,
          encoding=None, closest=False, progress=None, token=None, root_certificates=None, timeout=None,
          spacing=None, labels=False, black_border=False, nearest_label=False):
    """Computes a distance field on a distband server and returns it as a float32 numpy array (Z, Y, X).

    Exactly one seed source: ``mesh`` (path to .obj/.off/.ply/.stl), ``points`` ((x, y, z) world coordinates) or
    ``volume`` (bool/uint8/uint16/uint32 array (Z, Y, X), nonzero = seed; its values are labels). The grid: ``resolution`` or ``voxel_size`` around the
    seeds (``padding`` voxels of margin), or ``dims`` (x, y, z) + ``voxel_size`` (+ ``origin``); a volume's own
    shape by default. Voxels beyond ``limit`` (world units) or ``limit_voxels`` hold +limit (-limit inside a signed
    field), as in the CLI's .npy. With ``closest=True`` returns ``(field, closest)``: the index of each voxel's
    closest triangle / point (int32) or seed voxel (int64, linear in (Z, Y, X)), -1 where not delivered.
    ``progress(voxels_done, expected_voxels, segment)`` is called after each brick batch (expected_voxels 0 =
    unknown). ``token`` is sent as 'authorization: Bearer <token>'; ``root_certificates`` (PEM bytes) turns on TLS;
    ``timeout`` is the call's deadline in seconds. Volumes: ``spacing`` is the voxel size per axis in the array's
    order (Z, Y, X), as scipy's ``sampling``; ``labels=True`` computes the multi-label EDT (seung-lab edt's
    ``edt::edt``; ``black_border=True``: outside the grid is label 0); ``nearest_label=True`` returns
    ``(field, labels)``, each voxel's nearest seed label (int64, -1 where not delivered). Raises ValueError/TypeError for bad arguments (before
    connecting) and DistbandError for everything the server or the network reports. query_result() also returns
    the header (grid, limit, sign mode) and the summary.
    """
    r = query_result(server, mesh=mesh, points=points, volume=volume, resolution=resolution, voxel_size=voxel_size,
                     dims=dims, origin=origin, padding=padding, limit=limit, limit_voxels=limit_voxels, sign=sign,
                     mode=mode, stencil=stencil, segment_length=segment_length, encoding=encoding, closest=closest,
                     progress=progress, token=token, root_certificates=root_certificates, timeout=timeout,
                     spacing=spacing, labels=labels, black_border=black_border, nearest_label=nearest_label)
    return (r.field, r.closest) if closest or nearest_label else r.field
