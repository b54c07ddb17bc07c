#!/usr/bin/python3
"""The peer of bench/points_bench: Open3D's RaycastingScene (Debian python3-open3d 0.16) on the mesh and the query
points points_bench wrote, on the same thread count.

usage: open3d_points.py DIR THREADS REPEATS CHECK
  DIR/vertices.npy (V x 3 float32), DIR/triangles.npy (T x 3 uint32), DIR/points.npy (N x 3 float32)
Writes DIR/open3d_signed.npy and DIR/open3d_unsigned.npy (the first CHECK points' distances, float32) and prints one
JSON line: Open3D's version, the scene's build seconds and the median seconds of compute_distance and
compute_signed_distance over REPEATS runs on all N points. Exit 4 when open3d cannot be imported (the bench then
reports the peer as missing).
"""
import json
import sys
import time

import numpy as np

try:
    import open3d as o3d
except ImportError as e:  # the bench skips the peer
    print(json.dumps({"error": f"open3d: {e}"}))
    sys.exit(4)


def main():
    d, threads, repeats, check = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    vertices = np.load(f"{d}/vertices.npy")
    triangles = np.load(f"{d}/triangles.npy")
    points = o3d.core.Tensor(np.load(f"{d}/points.npy"))
    t0 = time.perf_counter()
    scene = o3d.t.geometry.RaycastingScene(nthreads=threads) if "nthreads" in (
        o3d.t.geometry.RaycastingScene.__init__.__doc__ or "") else o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(triangles))
    # Embree builds its BVH on the first query: one tiny query counts as the build.
    scene.compute_distance(o3d.core.Tensor(np.zeros((1, 3), np.float32)), nthreads=threads)
    build = time.perf_counter() - t0
    out = {"version": o3d.__version__, "build_seconds": build, "threads": threads}
    for name, fn in (("unsigned", scene.compute_distance), ("signed", scene.compute_signed_distance)):
        times = []
        result = None
        for _ in range(repeats):
            t = time.perf_counter()
            result = fn(points, nthreads=threads)
            times.append(time.perf_counter() - t)
        out[f"{name}_seconds"] = float(np.median(times))
        np.save(f"{d}/open3d_{name}.npy", result.numpy()[:check].astype(np.float32))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
