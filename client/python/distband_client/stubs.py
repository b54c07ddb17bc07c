"""The protobuf/gRPC modules generated from proto/distband/v1/distband.proto at build time.

The build writes them next to this package (build/python/distband/v1/); they are not in the source tree, so a
checkout imported without building gets an ImportError that says what to do.
"""
try:
    from distband.v1 import distband_pb2 as pb
    from distband.v1 import distband_pb2_grpc as rpc
except ImportError as e:  # pragma: no cover - only without a build
    raise ImportError(
        "distband_client needs the stubs generated from distband.proto: build them "
        "(ninja -C build distband-python) and put build/python on PYTHONPATH, "
        f"with Debian's /usr/bin/python3 (python3-grpcio, python3-protobuf) ({e})") from e

__all__ = ["pb", "rpc"]
