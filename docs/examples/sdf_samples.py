#!/usr/bin/python3
"""Training samples for an implicit model (DeepSDF-style, like mesh_to_sdf's sample_sdf_near_surface), through the
service: points near a mesh's surface and in its box, with their signed distance, saved as (points, sdf).

  PYTHONPATH=build/python /usr/bin/python3 docs/examples/sdf_samples.py 127.0.0.1:50051 MESH.obj OUT.npz [N]

Surface samples come from the mesh's own triangles (area-weighted), perturbed by Gaussians of two widths (0.25 % and
2.5 % of the box diagonal, as mesh_to_sdf does with its variance); 10 % of the points are uniform in the box grown by
10 % a side. The distances are exact to the nearest triangle and signed by the server's auto sign (pseudonormal for a
closed mesh, winding number for an open one), so open or messy meshes get well-defined signs.
"""
import sys

import numpy as np

import distband_client


def read_obj(path):
    v, f = [], []
    with open(path) as src:
        for line in src:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(c.split("/")[0]) - 1 for c in line.split()[1:]]
                f += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]  # fan polygons
    return np.array(v), np.array(f)


def main(server, mesh, out, n=250000):
    v, f = read_obj(mesh)
    rng = np.random.default_rng(0)
    lo, hi = v.min(0), v.max(0)
    diagonal = np.linalg.norm(hi - lo)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    n_surface = int(0.9 * n)
    t = rng.choice(len(f), n_surface, p=area / area.sum())
    u, w = rng.random((2, n_surface))
    flip = u + w > 1
    u[flip], w[flip] = 1 - u[flip], 1 - w[flip]
    surface = a[t] + u[:, None] * (b[t] - a[t]) + w[:, None] * (c[t] - a[t])
    sigma = np.where(rng.random(n_surface) < 0.5, 0.0025, 0.025)[:, None] * diagonal
    near = surface + rng.normal(size=surface.shape) * sigma
    size = hi - lo
    box = lo - 0.1 * size + 1.2 * size * rng.random((n - n_surface, 3))
    points = np.concatenate([near, box]).astype(np.float32)
    sdf = distband_client.distance_at(server, points, mesh=mesh)
    np.savez(out, points=points, sdf=sdf)
    print(f"{out}: {len(points)} points, {np.count_nonzero(sdf < 0)} inside")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3], *(int(x) for x in sys.argv[4:5]))
