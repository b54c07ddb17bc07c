#!/usr/bin/python3
"""A minimal distband.v1 client in Python on the raw protocol (the example of docs/protocol.md).

distband_client (docs/python.md) is the ready-made helper. The build generates the stubs this needs into
build/python; run it with Debian's interpreter (python3-grpcio, python3-protobuf):
  PYTHONPATH=build/python /usr/bin/python3 docs/examples/query.py 127.0.0.1:50051
or generate them by hand:
  mkdir -p py
  protoc -I proto --python_out=py --grpc_out=py --plugin=protoc-gen-grpc=/usr/bin/grpc_python_plugin \
      proto/distband/v1/distband.proto
"""
import sys
import grpc
import numpy as np
from distband.v1 import distband_pb2 as pb, distband_pb2_grpc as rpc

def query_points(target, points, dims, voxel_size=1.0, segment=4.0, limit=0.0):
    stub = rpc.DistanceFieldStub(grpc.insecure_channel(target))
    req = pb.QueryRequest(
        points=pb.PointList(points=[pb.Vec3(x=x, y=y, z=z) for x, y, z in points]),
        grid=pb.GridSpec(voxel_size=voxel_size, dims=pb.Dims(x=dims[0], y=dims[1], z=dims[2])),
        segment_length=segment, limit=limit)
    field = None
    for reply in stub.Query(req):
        kind = reply.WhichOneof("kind")
        if kind == "header":
            h = reply.header
            background = h.limit if np.isfinite(h.limit) else np.inf
            field = np.full((h.dims.z, h.dims.y, h.dims.x), background, np.float32)
            dtype = "<f2" if h.encoding == pb.BRICK_ENCODING_FLOAT16 else "<f4"
        elif kind == "bricks":
            for b in reply.bricks.bricks:
                offs = np.nonzero(np.unpackbits(np.frombuffer(b.mask, np.uint8), bitorder="little"))[0]
                field[b.z + (offs & 7), b.y + ((offs >> 3) & 7), b.x + (offs >> 6)] = np.frombuffer(b.values, dtype)
        elif kind == "segment_done":
            d = reply.segment_done
            print(f"segment {d.segment}: |d| in ({d.lower:g}, {d.upper:g}], {d.voxels} voxels", file=sys.stderr)
        elif kind == "summary":
            print(f"{reply.summary.voxels} voxels in {reply.summary.total_seconds:.3f} s", file=sys.stderr)
    return field


if __name__ == "__main__":
    # Usage: PYTHONPATH=build/python /usr/bin/python3 docs/examples/query.py HOST:PORT
    # Two points on a 40x32x24 grid; checks the streamed field against numpy brute force (exact for points).
    target = sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1:50051"
    pts, dims = [(5.2, 6.1, 7.7), (30.0, 20.5, 12.3)], (40, 32, 24)
    f = query_points(target, pts, dims, voxel_size=1.0, segment=4.0)
    z, y, x = np.meshgrid(*(np.arange(n, dtype=np.float64) for n in dims[::-1]), indexing="ij")
    ref = np.min([np.sqrt((x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2) for px, py, pz in pts], axis=0)
    err = np.abs(f.astype(np.float64) - ref).max()
    print(f"max |streamed - brute force| = {err:.2e}")
    sys.exit(0 if err < 1e-4 else 1)
