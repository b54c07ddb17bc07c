#!/usr/bin/env python3
"""Write a benchmark mesh as binary PLY from a bundled OFF or OBJ mesh: every triangle split in four, --levels times
(edge midpoints shared, so a closed mesh stays closed and the surface is unchanged), then --holes holes punched in it
(the triangles whose centroid lies within --hole-radius of the bounding box's diagonal from N triangles' centroids,
picked with a fixed seed): an open mesh as scans give them.

    bench/dense_mesh.py ../shared/data/meshes/armadillo.off --levels 3 --out /tmp/armadillo_3m.ply   # 3.33 M triangles
    bench/dense_mesh.py ../shared/data/meshes/bunny.obj --levels 0 --holes 8 --out /tmp/bunny_holes.ply
    bench/dense_mesh.py ../shared/data/meshes/bunny.obj --levels 0 --holes 8 --out /tmp/bunny_holes.stl   # a soup
"""
import argparse
import random
import struct
import sys


def read_off(path):
    words = open(path).read().split()
    if words[0] != "OFF":
        sys.exit(f"{path}: not an OFF file")
    nv, nf = int(words[1]), int(words[2])
    at = 4
    vertices = [tuple(float(w) for w in words[at + 3 * i:at + 3 * i + 3]) for i in range(nv)]
    at += 3 * nv
    triangles = []
    for _ in range(nf):
        k = int(words[at])
        if k != 3:
            sys.exit(f"{path}: a face with {k} vertices")
        triangles.append((int(words[at + 1]), int(words[at + 2]), int(words[at + 3])))
        at += 4
    return vertices, triangles


def read_obj(path):
    vertices, triangles = [], []
    for line in open(path):
        w = line.split()
        if not w:
            continue
        if w[0] == "v":
            vertices.append(tuple(float(x) for x in w[1:4]))
        elif w[0] == "f":
            idx = [int(x.split("/")[0]) for x in w[1:]]
            idx = [i - 1 if i > 0 else len(vertices) + i for i in idx]
            for k in range(1, len(idx) - 1):  # a fan for polygons
                triangles.append((idx[0], idx[k], idx[k + 1]))
    return vertices, triangles


def punch_holes(vertices, triangles, holes, radius):
    lo = [min(v[a] for v in vertices) for a in range(3)]
    hi = [max(v[a] for v in vertices) for a in range(3)]
    r = radius * sum((h - l) ** 2 for l, h in zip(lo, hi)) ** 0.5

    def centroid(t):
        return [sum(vertices[i][a] for i in t) / 3 for a in range(3)]

    rng = random.Random(7)
    centres = [centroid(triangles[rng.randrange(len(triangles))]) for _ in range(holes)]
    return [t for t in triangles
            if all(sum((x - y) ** 2 for x, y in zip(centroid(t), c)) > r * r for c in centres)]


def subdivide(vertices, triangles):
    midpoints = {}

    def mid(a, b):
        key = (a, b) if a < b else (b, a)
        m = midpoints.get(key)
        if m is None:
            m = midpoints[key] = len(vertices)
            va, vb = vertices[a], vertices[b]
            vertices.append(((va[0] + vb[0]) / 2, (va[1] + vb[1]) / 2, (va[2] + vb[2]) / 2))
        return m

    out = []
    for a, b, c in triangles:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    return vertices, out


def write_stl(path, vertices, triangles):
    """Binary STL: a triangle soup (each triangle with its own three corners and its unit normal)."""
    with open(path, "wb") as f:
        f.write(b"distband bench/dense_mesh.py".ljust(80, b" "))
        f.write(struct.pack("<I", len(triangles)))
        for t in triangles:
            a, b, c = (vertices[i] for i in t)
            u = [b[k] - a[k] for k in range(3)]
            v = [c[k] - a[k] for k in range(3)]
            n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
            length = sum(x * x for x in n) ** 0.5 or 1.0
            f.write(struct.pack("<12fH", *(x / length for x in n), *a, *b, *c, 0))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mesh")
    p.add_argument("--levels", type=int, default=3)
    p.add_argument("--holes", type=int, default=0)
    p.add_argument("--hole-radius", type=float, default=0.04, help="a fraction of the bounding box's diagonal")
    p.add_argument("--out", required=True)
    a = p.parse_args()
    vertices, triangles = read_obj(a.mesh) if a.mesh.endswith(".obj") else read_off(a.mesh)
    for _ in range(a.levels):
        vertices, triangles = subdivide(vertices, triangles)
    if a.holes:
        triangles = punch_holes(vertices, triangles, a.holes, a.hole_radius)
    if a.out.endswith(".stl"):
        write_stl(a.out, vertices, triangles)
        print(f"{a.out}: a soup of {len(triangles)} triangles")
        return
    with open(a.out, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                 "property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                 % (len(vertices), len(triangles))).encode())
        f.write(b"".join(struct.pack("<3f", *v) for v in vertices))
        f.write(b"".join(struct.pack("<B3i", 3, *t) for t in triangles))
    print(f"{a.out}: {len(vertices)} vertices, {len(triangles)} triangles")


if __name__ == "__main__":
    main()
