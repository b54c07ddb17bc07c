"""distband_client against real distband-server processes, checked against exact references.

Run by CTest (tests/CMakeLists.txt, label `python`), which sets
  PYTHONPATH             build/python (the package and its generated stubs)
  DISTBAND_SERVER_BINARY build/server/distband-server
  DISTBAND_CLI_BINARY    build/client/distband
  DISTBAND_SOURCE_DIR    the checkout (tests/data/meshes, docs/examples)
References: numpy brute force for point seeds (exact), scipy's EDT for volumes (<= 0.05 voxel), the CLI's .npy for
meshes (byte for byte).
"""
import io
import os
import subprocess
import sys
import tempfile
import time
import unittest

import numpy as np
from scipy import ndimage
from server_process import ServerProcess

import distband_client
from distband_client import DistbandError
from distband_client.assemble import FieldAssembler
from distband_client.stubs import pb

CLI = os.environ["DISTBAND_CLI_BINARY"]
SOURCE = os.environ["DISTBAND_SOURCE_DIR"]
BUNNY = os.path.join(SOURCE, "tests", "data", "meshes", "bunny.obj")
TOKEN = "python-client-test-token-0123456789"
UNUSED_TARGET = "127.0.0.1:1"  # nothing listens on port 1: a request that got that far would fail to connect


def voxel_centres(header):
    """World coordinates (Z, Y, X, 3) of every voxel, float64."""
    dx, dy, dz = header.dims
    z, y, x = np.meshgrid(np.arange(dz), np.arange(dy), np.arange(dx), indexing="ij")
    return np.stack([x, y, z], axis=-1) * header.voxel_size + np.array(header.origin)


def brute_force(points, centres):
    """Distances (float64) from every voxel to its nearest point, and the index of that point."""
    d = np.stack([np.linalg.norm(centres - p, axis=-1) for p in points])
    return d.min(axis=0), d.argmin(axis=0)


def ulp_tolerance(reference):
    """One float32 rounding of the largest distance: the engine computes in double and stores float32."""
    return float(np.spacing(np.float32(np.max(reference)))) + 1e-12


def seed_blobs(shape, seed):
    """A bool mask of a few balls and single voxels, away from the faces (so every x row that enters a blob
    leaves it through delivered voxels)."""
    rng = np.random.default_rng(seed)
    z, y, x = np.indices(shape)
    mask = np.zeros(shape, bool)
    for _ in range(4):
        c = [rng.uniform(8, n - 8) for n in shape]
        r = rng.uniform(2.5, 5.5)
        mask |= (z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2 <= r * r
    for _ in range(6):
        mask[tuple(int(rng.integers(6, n - 6)) for n in shape)] = True
    return mask


class ClientTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = ServerProcess()

    @classmethod
    def tearDownClass(cls):
        cls.server.stop()

    # ---- point seeds: exact -----------------------------------------------------------------------------------

    def test_points_match_brute_force_exactly_and_fill_beyond_the_limit(self):
        pts = [(3.3, 4.1, 2.7), (15.2, 11.9, 9.05), (-2.0, 20.0, 5.5)]
        r = distband_client.query_result(self.server.target, points=pts, dims=(40, 32, 24), voxel_size=0.5,
                                         origin=(-1.0, 2.0, 0.25), limit=3.0, segment_length=1.0)
        self.assertEqual(r.field.dtype, np.float32)
        self.assertEqual(r.field.shape, (24, 32, 40))
        self.assertEqual(r.header.shape, (24, 32, 40))
        self.assertEqual(r.header.dims, (40, 32, 24))
        self.assertEqual(r.header.origin, (-1.0, 2.0, 0.25))
        self.assertEqual(r.header.voxel_size, 0.5)
        self.assertEqual(r.header.limit, 3.0)
        self.assertFalse(r.header.signed)
        self.assertIsNone(r.closest)
        ref, _ = brute_force(pts, voxel_centres(r.header))
        near, far = ref < 3.0 - 1e-6, ref > 3.0 + 1e-6  # clear of float rounding at the limit
        self.assertGreater(near.sum(), 1000)
        self.assertGreater(far.sum(), 1000)
        self.assertLessEqual(np.abs(r.field[near] - ref[near]).max(), ulp_tolerance(ref[near]))
        self.assertTrue((r.field[far] == np.float32(3.0)).all(), "voxels beyond the limit hold +limit")
        self.assertTrue(near.sum() <= r.summary.voxels <= near.sum() + (~near & ~far).sum())

    def test_points_without_a_limit_cover_every_voxel(self):
        pts = [(5.2, 6.1, 7.7), (30.0, 20.5, 12.3)]
        field = distband_client.query(self.server.target, points=pts, dims=(40, 32, 24), voxel_size=1.0)
        z, y, x = np.indices(field.shape)
        ref = np.min([np.sqrt((x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2) for px, py, pz in pts], axis=0)
        self.assertTrue(np.isfinite(field).all())
        self.assertLessEqual(np.abs(field - ref).max(), ulp_tolerance(ref))

    def test_resolution_grid_matches_the_header(self):
        pts = [(0.0, 0.0, 0.0), (1.0, 2.0, 0.5)]
        r = distband_client.query_result(self.server.target, points=pts, resolution=33, padding=2)
        self.assertEqual(r.header.shape, r.field.shape)
        self.assertEqual(max(r.header.dims), 33)
        # 2 voxels of padding around the points' bounds, whose minimum is the origin (0, 0, 0).
        np.testing.assert_allclose(r.header.origin, [-2 * r.header.voxel_size] * 3, rtol=1e-12)
        ref, _ = brute_force(pts, voxel_centres(r.header))
        self.assertLessEqual(np.abs(r.field - ref).max(), ulp_tolerance(ref))

    def test_float16_encoding_is_the_float32_field_rounded(self):
        pts = [(4.25, 9.5, 3.0)]
        args = dict(points=pts, dims=(24, 24, 16), voxel_size=0.75, limit=6.0, segment_length=2.0)
        f32 = distband_client.query(self.server.target, **args)
        f16 = distband_client.query(self.server.target, encoding="float16", **args)
        self.assertEqual(f16.dtype, np.float32)
        np.testing.assert_array_equal(f16, f32.astype(np.float16).astype(np.float32))

    # ---- closest features ------------------------------------------------------------------------------------

    def test_closest_point_gives_exactly_the_delivered_distance(self):
        rng = np.random.default_rng(7)
        pts = rng.uniform([-2, -2, -2], [26, 22, 18], size=(9, 3))
        limit = 6.0
        field, closest = distband_client.query(self.server.target, points=pts, dims=(24, 20, 16), voxel_size=1.0,
                                               limit=limit, segment_length=2.0, closest=True)
        self.assertEqual(closest.dtype, np.int32)
        self.assertEqual(closest.shape, field.shape)
        delivered = closest >= 0
        self.assertGreater(delivered.sum(), 1000)
        self.assertTrue((field[~delivered] == np.float32(limit)).all(), "undelivered voxels hold +limit")
        self.assertLess(closest.max(), len(pts))
        z, y, x = np.nonzero(delivered)
        centres = np.stack([x, y, z], axis=-1).astype(np.float64)
        via_index = np.linalg.norm(centres - pts[closest[delivered]], axis=-1)
        ref, _ = brute_force(pts, centres)
        tol = ulp_tolerance(ref)
        self.assertLessEqual(np.abs(field[delivered] - via_index).max(), tol,
                             "the returned point must be at exactly the delivered distance")
        self.assertLessEqual(np.abs(via_index - ref).max(), 1e-12, "the returned point must be a nearest one")

    def test_closest_voxel_is_a_seed_at_the_delivered_distance(self):
        mask = seed_blobs((20, 24, 28), seed=3)
        field, closest = distband_client.query(self.server.target, volume=mask, limit_voxels=5, closest=True)
        self.assertEqual(closest.dtype, np.int64)
        delivered = closest >= 0
        self.assertGreater(delivered.sum(), 1000)
        self.assertTrue(mask.ravel()[closest[delivered]].all(), "a closest voxel must be a seed voxel")
        z, y, x = np.nonzero(delivered)
        cz, cy, cx = np.unravel_index(closest[delivered], mask.shape)
        via_index = np.sqrt((x - cx) ** 2.0 + (y - cy) ** 2.0 + (z - cz) ** 2.0)
        self.assertLessEqual(np.abs(field[delivered] - via_index).max(), ulp_tolerance(via_index))

    # ---- volumes: scipy's EDT ----------------------------------------------------------------------------------

    def test_unsigned_volume_matches_scipy_edt(self):
        mask = seed_blobs((32, 36, 40), seed=1)
        for voxel_size in (1.0, 0.5):
            r = distband_client.query_result(self.server.target, volume=mask, voxel_size=voxel_size)
            self.assertEqual(r.field.shape, mask.shape)
            self.assertEqual(r.header.sign, "unsigned")
            ref = ndimage.distance_transform_edt(mask == 0, sampling=voxel_size)
            self.assertLessEqual(np.abs(r.field - ref).max(), 0.05 * voxel_size, f"voxel_size {voxel_size}")

    def test_signed_volume_matches_scipy_and_fills_the_inside_with_minus_limit(self):
        mask = seed_blobs((32, 36, 40), seed=2).astype(np.uint8)
        ref = ndimage.distance_transform_edt(mask == 0) - ndimage.distance_transform_edt(mask != 0)
        full = distband_client.query(self.server.target, volume=mask, sign="mask-inside")
        self.assertLessEqual(np.abs(full - ref).max(), 0.05)
        r = distband_client.query_result(self.server.target, volume=mask, sign="mask-inside", limit=2.0,
                                         segment_length=1.0)
        self.assertTrue(r.header.signed)
        self.assertEqual(r.header.sign, "mask-inside")
        inside, outside = ref < -2.0 - 1e-6, ref > 2.0 + 1e-6
        self.assertGreater(inside.sum(), 50, "the blobs must be deeper than the limit for this check")
        self.assertTrue((r.field[inside] == np.float32(-2.0)).all(), "undelivered inside voxels hold -limit")
        self.assertTrue((r.field[outside] == np.float32(2.0)).all(), "undelivered outside voxels hold +limit")
        band = np.abs(ref) < 2.0 - 1e-6
        self.assertLessEqual(np.abs(r.field[band] - ref[band]).max(), 0.05)

    def test_label_volume_with_spacing_in_numpys_axis_order(self):
        rng = np.random.default_rng(5)
        labels = np.kron(rng.integers(0, 5, size=(6, 7, 8)), np.ones((4, 4, 4), np.int64)).astype(np.uint16)
        sampling = (2.5, 0.5, 0.7)  # (Z, Y, X), as scipy's
        r = distband_client.query_result(self.server.target, volume=labels, spacing=sampling, labels=True,
                                         black_border=True)
        self.assertEqual(r.header.spacing, (0.7, 0.5, 2.5))
        self.assertTrue(r.header.labels and r.header.black_border)
        padded = np.pad(labels, 1)
        ref = np.zeros(labels.shape)
        for v in np.unique(labels[labels > 0]):
            d = ndimage.distance_transform_edt(padded == v, sampling=sampling)[1:-1, 1:-1, 1:-1]
            ref[labels == v] = d[labels == v]
        self.assertLessEqual(float(np.max(np.abs(r.field - ref) / (1 + ref))), 1e-5)
        field, nearest = distband_client.query(self.server.target, volume=labels, spacing=sampling,
                                               nearest_label=True)
        _, idx = ndimage.distance_transform_edt(labels == 0, sampling=sampling, return_indices=True)
        per = np.sort(np.stack([ndimage.distance_transform_edt(labels != v, sampling=sampling)
                                for v in np.unique(labels[labels > 0])]), axis=0)
        unique = per[1] - per[0] > 1e-4
        np.testing.assert_array_equal(nearest[unique], labels[tuple(idx)][unique])
        with self.assertRaises(ValueError):
            distband_client.query(self.server.target, volume=labels, black_border=True)
        with self.assertRaises(ValueError):
            distband_client.query(self.server.target, points=[(1.0, 2.0, 3.0)], voxel_size=1.0, labels=True)

    # ---- meshes: the CLI's .npy, byte for byte ---------------------------------------------------------------

    def test_mesh_field_is_byte_identical_to_the_cli_npy(self):
        with tempfile.TemporaryDirectory() as tmp:
            for encoding in ("float32", "float16"):
                cli_npy = os.path.join(tmp, f"bunny-{encoding}.npy")
                subprocess.run([CLI, "query", "--server", self.server.target, "--mesh", BUNNY, "--resolution", "48",
                                "--limit-voxels", "3", "--segment", "0.01", "--encoding", encoding, "--progress",
                                "quiet", "--npy", cli_npy], check=True, capture_output=True, timeout=300)
                r = distband_client.query_result(self.server.target, mesh=BUNNY, resolution=48, limit_voxels=3,
                                                 segment_length=0.01, encoding=encoding)
                self.assertTrue(r.header.signed)
                self.assertGreater((r.field < 0).sum(), 1000, "the bunny's inside must be negative")
                ours = io.BytesIO()
                np.save(ours, r.field)
                with open(cli_npy, "rb") as f:
                    theirs = f.read()
                self.assertEqual(np.load(io.BytesIO(theirs)).shape, r.field.shape)
                self.assertTrue(ours.getvalue() == theirs, f"{encoding}: the .npy bytes differ from the CLI's")

    # ---- progress ----------------------------------------------------------------------------------------------

    def test_progress_reports_growing_counts_per_batch(self):
        calls = []
        r = distband_client.query_result(self.server.target, points=[(10.0, 30.0, 20.0)], dims=(64, 64, 48),
                                         voxel_size=1.0, limit=40.0, segment_length=4.0,
                                         progress=lambda *a: calls.append(a))
        self.assertGreaterEqual(len(calls), len(r.summary.segments))
        done = [c[0] for c in calls]
        segments = [c[2] for c in calls]
        self.assertTrue(all(b > a for a, b in zip(done, done[1:])), "voxels_done must grow with every batch")
        self.assertTrue(all(b >= a for a, b in zip(segments, segments[1:])), "segments arrive in order")
        self.assertEqual(done[-1], r.summary.voxels)
        self.assertEqual(segments[-1], len(r.summary.segments) - 1)
        self.assertTrue(all(c[1] == r.header.expected_voxels for c in calls))
        ref, _ = brute_force([(10.0, 30.0, 20.0)], voxel_centres(r.header))
        near, far = ref < 40.0 - 1e-6, ref > 40.0 + 1e-6
        self.assertTrue(near.sum() <= done[-1] <= near.sum() + (~near & ~far).sum())

    def test_an_exception_in_progress_cancels_the_query(self):
        def stop(*_):
            raise KeyboardInterrupt

        t0 = time.monotonic()
        with self.assertRaises(KeyboardInterrupt):
            distband_client.query(self.server.target, points=[(1.0, 2.0, 3.0)], dims=(256, 256, 256),
                                  voxel_size=1.0, segment_length=1.0, progress=stop)
        self.assertLess(time.monotonic() - t0, 20)
        # The server is still serving (and the cancelled query left no slot taken).
        field = distband_client.query(self.server.target, points=[(0.0, 0.0, 0.0)], dims=(8, 8, 8), voxel_size=1.0)
        self.assertEqual(field[0, 0, 0], 0.0)

    def test_timeout_is_the_calls_deadline(self):
        with self.assertRaises(DistbandError) as e:
            distband_client.query(self.server.target, points=[(1.0, 2.0, 3.0)], dims=(256, 256, 256),
                                  voxel_size=1.0, timeout=0.05)
        self.assertEqual(e.exception.code, "DEADLINE_EXCEEDED")

    # ---- errors --------------------------------------------------------------------------------------------------

    def assertRefused(self, exception, fragment, **kwargs):
        """The arguments are refused before any connection (the target has no server) with a message naming them."""
        with self.assertRaises(exception) as e:
            distband_client.query(UNUSED_TARGET, **kwargs)
        self.assertIn(fragment, str(e.exception))

    def test_bad_arguments_are_refused_before_connecting_naming_the_argument(self):
        pts = [(1.0, 2.0, 3.0)]
        self.assertRefused(ValueError, "give exactly one seed source", resolution=32)
        self.assertRefused(ValueError, "points and volume", points=pts, volume=np.ones((4, 4, 4), bool))
        self.assertRefused(ValueError, "resolution and voxel_size", points=pts, resolution=32, voxel_size=0.5)
        self.assertRefused(ValueError, "resolution and voxel_size", points=pts)
        self.assertRefused(ValueError, "dims needs voxel_size", points=pts, dims=(8, 8, 8))
        self.assertRefused(ValueError, "origin", points=pts, resolution=32, origin=(0, 0, 0))
        self.assertRefused(TypeError, "resolution", points=pts, resolution="32")
        self.assertRefused(ValueError, "resolution must be >= 2", points=pts, resolution=1)
        self.assertRefused(ValueError, "voxel_size must be > 0", points=pts, voxel_size=-1.0)
        self.assertRefused(ValueError, "limit and limit_voxels", points=pts, resolution=32, limit=1, limit_voxels=2)
        self.assertRefused(ValueError, "limit_voxels must be finite", points=pts, resolution=32,
                           limit_voxels=float("inf"))
        self.assertRefused(ValueError, "segment_length", points=pts, resolution=32, segment_length=-1)
        self.assertRefused(ValueError, "points[1]", points=[(0, 0, 0), (1, float("nan"), 2)], resolution=32)
        self.assertRefused(ValueError, "points must have shape (N, 3)", points=[(0, 0)], resolution=32)
        self.assertRefused(ValueError, "dims must have 3", points=pts, dims=(8, 8), voxel_size=1.0)
        self.assertRefused(ValueError, "mesh='bunny.txt': unsupported mesh format", mesh="bunny.txt", resolution=32)
        self.assertRefused(ValueError, "cannot read the file", mesh="/nonexistent/bunny.obj", resolution=32)
        self.assertRefused(TypeError, "volume must have dtype bool, uint8, uint16 or uint32", volume=np.ones((4, 4, 4)))
        self.assertRefused(ValueError, "volume must be 3-D", volume=np.ones((4, 4), bool))
        self.assertRefused(ValueError, "resolution cannot be combined", volume=np.ones((4, 4, 4), bool),
                           resolution=8)
        self.assertRefused(ValueError, "sign='signed'", points=pts, resolution=32, sign="signed")
        self.assertRefused(ValueError, "stencil=", points=pts, resolution=32, stencil="cubic27")
        self.assertRefused(ValueError, "encoding=", points=pts, resolution=32, encoding="int8")
        self.assertRefused(TypeError, "progress must be callable", points=pts, resolution=32, progress=3)
        self.assertRefused(ValueError, "timeout", points=pts, resolution=32, timeout=0)
        self.assertRefused(TypeError, "closest must be True or False", points=pts, resolution=32, closest="yes")
        self.assertRefused(ValueError, "token must be printable", points=pts, resolution=32, token="a b")

    def test_server_refusals_raise_distband_error_with_code_and_field(self):
        with self.assertRaises(DistbandError) as e:
            distband_client.query(self.server.target, points=[(1.0, 2.0, 3.0)], resolution=32, padding=5000)
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertIn("grid.padding", e.exception.details)
        self.assertIn("grid.padding", str(e.exception))
        with self.assertRaises(DistbandError) as e:
            distband_client.query(self.server.target, mesh=BUNNY, resolution=16, sign="mask-inside")
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertIn("sign", e.exception.details)

    def test_a_malformed_mesh_is_refused_by_the_server(self):
        with tempfile.NamedTemporaryFile("w", suffix=".obj") as f:
            f.write("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
            f.flush()
            with self.assertRaises(DistbandError) as e:
                distband_client.query(self.server.target, mesh=f.name, resolution=16)
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")

    def test_an_unreachable_server_raises_unavailable(self):
        with self.assertRaises(DistbandError) as e:
            distband_client.query(UNUSED_TARGET, points=[(1.0, 2.0, 3.0)], resolution=16, timeout=10)
        self.assertEqual(e.exception.code, "UNAVAILABLE")

    # ---- the protocol doc's raw example ------------------------------------------------------------------------

    def test_docs_example_runs_against_the_server(self):
        example = os.path.join(SOURCE, "docs", "examples", "query.py")
        p = subprocess.run([sys.executable, example, self.server.target], capture_output=True, text=True, timeout=120)
        self.assertEqual(p.returncode, 0, p.stdout + p.stderr)
        self.assertIn("max |streamed - brute force| =", p.stdout)


class AssemblerTest(unittest.TestCase):
    """The brick decoding on hand-made messages: layout, closest ids, the CLI's sign fill, protocol checks."""

    @staticmethod
    def brick(origin, voxels, closest_dtype=None):
        """A BrickData holding {(lx, ly, lz): (value, closest id)} at `origin` (x, y, z)."""
        mask = bytearray(64)
        entries = sorted(((lx << 6) | (ly << 3) | lz, v) for (lx, ly, lz), v in voxels.items())
        for offset, _ in entries:
            mask[offset // 8] |= 1 << (offset % 8)
        values = np.array([v for _, (v, _) in entries], "<f4").tobytes()
        ids = np.array([c for _, (_, c) in entries], closest_dtype).tobytes() if closest_dtype else b""
        return pb.BrickData(x=origin[0], y=origin[1], z=origin[2], mask=bytes(mask), values=values, closest=ids)

    def header(self, **kwargs):
        return pb.QueryHeader(dims=pb.Dims(x=10, y=9, z=3), limit=2.0, encoding=pb.BRICK_ENCODING_FLOAT32, **kwargs)

    def test_values_closest_ids_and_the_signs_of_undelivered_voxels(self):
        a = FieldAssembler(self.header(signed=True, closest_feature=pb.CLOSEST_FEATURE_VOXEL), want_closest=True)
        batch = pb.BrickBatch(bricks=[
            self.brick((0, 0, 0), {(3, 2, 0): (0.25, 7), (6, 2, 0): (-0.25, 1 << 40)}, "<i8"),
            # x = 9 is inside the grid (dims.x = 10), x = 11 is not: ignored, as the CLI does.
            self.brick((8, 0, 0), {(1, 2, 0): (-0.5, 12345), (3, 2, 0): (-0.75, 5)}, "<i8")])
        self.assertEqual(a.add(batch), 4)
        field, closest = a.finish()
        self.assertEqual(closest.dtype, np.int64)
        self.assertEqual((field[0, 2, 3], field[0, 2, 6], field[0, 2, 9]), (0.25, -0.25, -0.5))
        self.assertEqual((closest[0, 2, 3], closest[0, 2, 6], closest[0, 2, 9]), (7, 1 << 40, 12345))
        self.assertEqual((closest >= 0).sum(), 3)
        # Row (z 0, y 2): before x 3 the first delivered voxel's sign (+), then the sign of the nearest delivered
        # voxel before each undelivered one; every other row has no delivered voxel and stays +limit.
        np.testing.assert_array_equal(field[0, 2], [2, 2, 2, 0.25, 2, 2, -0.25, -2, -2, -0.5])
        others = np.ones(field.shape, bool)
        others[0, 2] = False
        self.assertTrue((field[others] == 2.0).all())

    def test_float16_values_and_int32_ids(self):
        h = self.header(signed=False, closest_feature=pb.CLOSEST_FEATURE_POINT)
        h.encoding = pb.BRICK_ENCODING_FLOAT16
        a = FieldAssembler(h, want_closest=True)
        b = self.brick((0, 8, 0), {(1, 0, 2): (0.0, 3)}, "<i4")
        b.values = np.array([1.0009765625], "<f2").tobytes()  # 1 + 2^-10, exact in float16
        a.add(pb.BrickBatch(bricks=[b]))
        field, closest = a.finish()
        self.assertEqual(closest.dtype, np.int32)
        self.assertEqual(field[2, 8, 1], np.float32(1.0009765625))
        self.assertEqual(closest[2, 8, 1], 3)
        self.assertEqual((field == 2.0).sum(), field.size - 1, "unsigned: undelivered voxels hold +limit")

    def test_malformed_bricks_are_protocol_errors(self):
        a = FieldAssembler(self.header(signed=False, closest_feature=pb.CLOSEST_FEATURE_POINT), want_closest=True)
        cases = {"closest features": self.brick((0, 0, 0), {(0, 0, 0): (1.0, 0)}, "<i8"),  # int64 for POINT
                 "values": pb.BrickData(x=0, y=0, z=0, mask=b"\x01" + bytes(63), values=b""),
                 "64 bytes": pb.BrickData(x=0, y=0, z=0, mask=b"\x01", values=bytes(4)),
                 "multiple of 8": self.brick((4, 0, 0), {(0, 0, 0): (1.0, 0)}, "<i4")}
        for what, brick in cases.items():
            with self.assertRaises(DistbandError) as e:
                a.add(pb.BrickBatch(bricks=[brick]))
            self.assertEqual(e.exception.code, "PROTOCOL")
            self.assertIn(what, e.exception.details)

    def test_closest_from_a_server_without_them_is_refused(self):
        with self.assertRaises(DistbandError) as e:
            FieldAssembler(self.header(signed=False), want_closest=True)
        self.assertEqual(e.exception.code, "UNIMPLEMENTED")


class AuthenticatedServerTest(unittest.TestCase):
    """A server with --auth-token-file and TLS: the token travels as 'authorization: Bearer <token>'."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        d = cls.tmp.name
        with open(os.path.join(d, "tokens"), "w") as f:
            f.write(f"# test token\n{TOKEN}\n")
        # A self-signed certificate for 127.0.0.1, its own CA (as tests/integration/hardening_test.cc makes it).
        subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                        "-nodes", "-days", "2", "-subj", "/CN=localhost",
                        "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1",
                        "-addext", "basicConstraints=critical,CA:TRUE",
                        "-keyout", os.path.join(d, "server.key"), "-out", os.path.join(d, "server.pem")],
                       check=True, capture_output=True)
        with open(os.path.join(d, "server.pem"), "rb") as f:
            cls.ca = f.read()
        cls.server = ServerProcess("--auth-token-file", os.path.join(d, "tokens"),
                                   "--tls-cert", os.path.join(d, "server.pem"),
                                   "--tls-key", os.path.join(d, "server.key"))

    @classmethod
    def tearDownClass(cls):
        cls.server.stop()
        cls.tmp.cleanup()

    def query(self, **kwargs):
        return distband_client.query(self.server.target, points=[(1.0, 2.0, 3.0)], dims=(8, 8, 8), voxel_size=1.0,
                                     timeout=30, **kwargs)

    def test_the_right_token_over_tls_is_served(self):
        field = self.query(token=TOKEN, root_certificates=self.ca)
        z, y, x = np.indices(field.shape)
        ref = np.sqrt((x - 1.0) ** 2 + (y - 2.0) ** 2 + (z - 3.0) ** 2)
        self.assertLessEqual(np.abs(field - ref).max(), ulp_tolerance(ref))
        # PEM given as text works the same.
        self.assertTrue((self.query(token=TOKEN, root_certificates=self.ca.decode()) == field).all())

    def test_a_missing_or_wrong_token_is_unauthenticated(self):
        with self.assertRaises(DistbandError) as e:
            self.query(root_certificates=self.ca)
        self.assertEqual(e.exception.code, "UNAUTHENTICATED")
        self.assertIn("authorization", e.exception.details)
        with self.assertRaises(DistbandError) as e:
            self.query(token=TOKEN + "x", root_certificates=self.ca)
        self.assertEqual(e.exception.code, "UNAUTHENTICATED")
        self.assertIn("not valid", e.exception.details)

    def test_plaintext_to_a_tls_server_fails_to_connect(self):
        with self.assertRaises(DistbandError) as e:
            self.query(token=TOKEN)
        self.assertEqual(e.exception.code, "UNAVAILABLE")


class DistanceAtTest(unittest.TestCase):
    """distance_at() through QueryPoints, against exact distances computed here (seed points: numpy brute force)."""

    @classmethod
    def setUpClass(cls):
        cls.server = ServerProcess()

    @classmethod
    def tearDownClass(cls):
        cls.server.stop()

    def test_seed_points_exact_in_order_over_several_chunks(self):
        rng = np.random.default_rng(4)
        seeds = rng.uniform(-1, 1, (7, 3))
        at = rng.uniform(-2, 2, (5000, 3))
        d = distband_client.distance_at(self.server.target, at, points=seeds, chunk_points=777)
        exact = np.sqrt(((at[:, None, :] - seeds[None, :, :]) ** 2).sum(-1))
        self.assertEqual(d.dtype, np.float64)
        np.testing.assert_allclose(d, exact.min(1), rtol=0, atol=1e-12)
        r = distband_client.distance_at(self.server.target, at.astype(np.float32), points=seeds, ids=True,
                                        closest_points=True, gradient=True, limit=1.0)
        self.assertEqual(r["distance"].dtype, np.float32)
        near = exact.min(1) <= 1.0
        np.testing.assert_array_equal(r["ids"][near], exact.argmin(1)[near])
        np.testing.assert_array_equal(r["ids"][~near], -1)
        np.testing.assert_array_equal(r["distance"][~near], np.float32(1.0))
        np.testing.assert_allclose(r["closest_points"][near], seeds[r["ids"][near]], atol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(r["gradient"][near], axis=1), 1, atol=1e-5)

    def test_mesh_equals_the_cli_in_process(self):
        rng = np.random.default_rng(9)
        with open(BUNNY) as f:
            v = np.array([line.split()[1:4] for line in f if line.startswith("v ")], dtype=np.float64)
        at = rng.uniform(v.min(0), v.max(0), (2000, 3)).astype(np.float32)
        r = distband_client.distance_at(self.server.target, at, mesh=BUNNY, ids=True)
        with tempfile.TemporaryDirectory() as d:
            np.save(os.path.join(d, "q.npy"), at)
            subprocess.run([CLI, "at", "--mesh", BUNNY, "--at", os.path.join(d, "q.npy"), "--out",
                            os.path.join(d, "d.npy"), "--closest", os.path.join(d, "i.npy")], check=True,
                           capture_output=True)
            np.testing.assert_array_equal(r["distance"], np.load(os.path.join(d, "d.npy")))
            np.testing.assert_array_equal(r["ids"], np.load(os.path.join(d, "i.npy")))
        self.assertTrue((r["distance"] < 0).any() and (r["distance"] > 0).any())

    def test_bad_arguments_and_server_refusals(self):
        with self.assertRaises(ValueError):
            distband_client.distance_at(self.server.target, [[0, 0, float("nan")]], points=[(0, 0, 0)])
        with self.assertRaises(ValueError):
            distband_client.distance_at(self.server.target, np.zeros((3, 2)), points=[(0, 0, 0)])
        with self.assertRaises(ValueError):
            distband_client.distance_at(self.server.target, np.zeros((3, 3)))
        with self.assertRaises(DistbandError) as e:
            distband_client.distance_at(self.server.target, np.zeros((3, 3)), points=[(0, 0, 0)], sign="winding")
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertIn("sign", e.exception.details)


if __name__ == "__main__":
    unittest.main(verbosity=2)
