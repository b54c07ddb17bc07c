"""Volume files, anisotropic spacing and label volumes through the `distband` CLI, checked against scipy.

Run by CTest (tests/CMakeLists.txt, label `python`) with Debian's interpreter (python3-numpy, -scipy, -nibabel), which
sets DISTBAND_CLI_BINARY (build/client/distband) and, for `distband query` through one server and through a
coordinator over three replicas on loopback, DISTBAND_SERVER_BINARY (build/server/distband-server).
References (never distband's own output): scipy.ndimage.distance_transform_edt with `sampling` for the seed field,
its `return_indices` label lookup for nearest labels (where the nearest label is unique), and the multi-label EDT as
edt::edt defines it, per label L the EDT of (labels == L) (the distance to the nearest voxel of another label), with
a zero border padded around the volume for the black border.
NIfTI files are written by nibabel; NRRD files by hand in the layout pynrrd writes (NRRD0004, space directions, space
origin, gzip encoding).
"""
import gzip
import os
import re
import subprocess
import tempfile
import unittest

import nibabel as nib
import numpy as np
from scipy import ndimage
from server_process import ServerProcess

CLI = os.environ["DISTBAND_CLI_BINARY"]
SERVER = os.environ.get("DISTBAND_SERVER_BINARY")
SPACING_XYZ = (0.7, 0.7, 2.5)
ORIGIN = (10.0, -20.0, 30.0)


def label_volume(shape_zyx, labels, seed):
    """Blocky random labels, shape (Z, Y, X), 0 the background."""
    rng = np.random.default_rng(seed)
    coarse = rng.integers(0, labels + 1, size=tuple((s + 3) // 4 for s in shape_zyx))
    vol = np.kron(coarse, np.ones((4, 4, 4), dtype=np.int64))[: shape_zyx[0], : shape_zyx[1], : shape_zyx[2]]
    vol[rng.random(shape_zyx) < 0.02] = 0
    return vol.astype(np.uint16)


def multi_label_edt(labels, sampling_zyx, black_border):
    out = np.zeros(labels.shape, dtype=np.float64)
    lab = np.pad(labels, 1) if black_border else labels
    for value in np.unique(labels):
        if value == 0:
            continue
        d = ndimage.distance_transform_edt(lab == value, sampling=sampling_zyx)
        if black_border:
            d = d[1:-1, 1:-1, 1:-1]
        out[labels == value] = d[labels == value]
    return out


def float32_spacing_zyx():
    """The spacing as a NIfTI header stores it (float32), in numpy's (Z, Y, X) order."""
    s = np.float32(SPACING_XYZ).astype(np.float64)
    return (s[2], s[1], s[0])


def write_nifti(path, labels_zyx):
    affine = np.diag([*SPACING_XYZ, 1.0])
    affine[:3, 3] = ORIGIN
    nib.save(nib.Nifti1Image(np.ascontiguousarray(labels_zyx.transpose(2, 1, 0)), affine), path)
    return affine


def write_nrrd(path, labels_zyx):
    z, y, x = labels_zyx.shape
    s = [float(v) for v in np.float32(SPACING_XYZ)]  # the same spacing as the NIfTI's, so the fields agree exactly
    header = (
        "NRRD0004\n# Complete NRRD file format specification at:\n# http://teem.sourceforge.net/nrrd/format.html\n"
        f"type: uint16\ndimension: 3\nspace: left-posterior-superior\nsizes: {x} {y} {z}\n"
        f"space directions: ({s[0]!r},0,0) (0,{s[1]!r},0) (0,0,{s[2]!r})\nkinds: domain domain domain\n"
        f"endian: little\nencoding: gzip\nspace origin: ({ORIGIN[0]!r},{ORIGIN[1]!r},{ORIGIN[2]!r})\n\n")
    with open(path, "wb") as f:
        f.write(header.encode() + gzip.compress(labels_zyx.astype("<u2").tobytes()))


def run(*args):
    p = subprocess.run([CLI, *args], capture_output=True, text=True)
    if p.returncode != 0:
        raise AssertionError(f"distband {' '.join(args)} exited {p.returncode}:\n{p.stdout}\n{p.stderr}")
    return p.stdout


def rel_err(a, b):
    return float(np.max(np.abs(a.astype(np.float64) - b) / (1.0 + np.abs(b))))


class VolumeFilesThroughTheCli(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.dir = cls.tmp.name
        cls.labels = label_volume((20, 26, 30), 5, seed=7)
        np.save(cls.path("labels.npy"), cls.labels)
        cls.affine = write_nifti(cls.path("labels.nii.gz"), cls.labels)
        write_nifti(cls.path("labels.nii"), cls.labels)
        write_nrrd(cls.path("labels.nrrd"), cls.labels)
        cls.spacing_flag = ",".join(repr(float(v)) for v in np.float32(SPACING_XYZ))

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    @classmethod
    def path(cls, name):
        return os.path.join(cls.dir, name)

    def compute(self, volume, out, *flags):
        run("compute", "--volume", self.path(volume), "--out", self.path(out), *flags)
        return np.load(self.path(out)) if out.endswith(".npy") else None

    def test_seed_field_with_spacing_matches_scipy_sampling_for_every_format(self):
        exact = ndimage.distance_transform_edt(self.labels == 0, sampling=float32_spacing_zyx())
        npy = self.compute("labels.npy", "npy.npy", "--spacing", self.spacing_flag)
        self.assertLessEqual(rel_err(npy, exact), 1e-5)
        for name in ("labels.nii.gz", "labels.nii", "labels.nrrd"):
            field = self.compute(name, name + ".field.npy")
            np.testing.assert_array_equal(field, npy, err_msg=f"{name} (its header's spacing) vs the .npy with --spacing")

    def test_multi_label_edt_matches_the_reference_with_and_without_black_border(self):
        for black in (False, True):
            flags = ["--labels"] + (["--black-border"] if black else [])
            field = self.compute("labels.nii.gz", f"ml{black}.npy", *flags)
            exact = multi_label_edt(self.labels, float32_spacing_zyx(), black)
            self.assertLessEqual(rel_err(field, exact), 1e-5, f"black border {black}")
            limited = self.compute("labels.nrrd", f"ml{black}_limit.npy", *flags, "--limit", "2.0")
            inside = exact <= 2.0
            self.assertLessEqual(rel_err(limited[inside], exact[inside]), 1e-5)
            self.assertTrue(np.all(limited[~inside] == np.float32(2.0)), "beyond the limit: the limit")

    def test_nearest_labels_match_scipys_indices_where_the_nearest_label_is_unique(self):
        sampling = float32_spacing_zyx()
        self.compute("labels.nii.gz", "nl_field.npy", "--nearest-label", self.path("nl.npy"))
        nearest = np.load(self.path("nl.npy"))
        _, idx = ndimage.distance_transform_edt(self.labels == 0, sampling=sampling, return_indices=True)
        reference = self.labels[tuple(idx)]
        per_label = np.sort(np.stack([ndimage.distance_transform_edt(self.labels != v, sampling=sampling)
                                      for v in np.unique(self.labels) if v != 0]), axis=0)
        unique = per_label[1] - per_label[0] > 1e-4
        self.assertGreater(unique.sum(), 0.9 * unique.size)
        np.testing.assert_array_equal(nearest[unique], reference[unique])

    def test_nifti_output_has_the_inputs_affine(self):
        self.compute("labels.nii.gz", "field.nii.gz", "--labels")
        image = nib.load(self.path("field.nii.gz"))
        np.testing.assert_allclose(image.affine, self.affine, rtol=0, atol=1e-6)
        data = np.asarray(image.dataobj).transpose(2, 1, 0)
        np.testing.assert_array_equal(data, self.compute("labels.nii.gz", "field_same.npy", "--labels"))

    def test_spacing_flag_overrides_the_header(self):
        field = self.compute("labels.nii.gz", "override.npy", "--spacing", "1,1,1")
        exact = ndimage.distance_transform_edt(self.labels == 0)
        self.assertLessEqual(rel_err(field, exact), 1e-5)

    def test_hostile_files_are_refused_with_a_message(self):
        with open(self.path("labels.nrrd"), "rb") as f:
            good = f.read()
        for name, data, expect in (("cut.nrrd", good[:-40], "nrrd"),
                                   ("rotated.nii", None, "rotated or sheared"),
                                   ("junk.nii", b"x" * 400, "not a NIfTI file")):
            if data is None:
                affine = np.array([[0.6, 0.35, 0, 0], [-0.35, 0.6, 0, 0], [0, 0, 2.5, 0], [0, 0, 0, 1.0]])
                nib.save(nib.Nifti1Image(np.ascontiguousarray(self.labels.transpose(2, 1, 0)), affine),
                         self.path(name))
            else:
                with open(self.path(name), "wb") as f:
                    f.write(data)
            p = subprocess.run([CLI, "compute", "--volume", self.path(name), "--out", self.path("x.npy")],
                               capture_output=True, text=True)
            self.assertEqual(p.returncode, 2, p.stdout + p.stderr)
            self.assertIn(expect, p.stderr.lower() if expect == "nrrd" else p.stderr)


@unittest.skipUnless(SERVER, "DISTBAND_SERVER_BINARY not set")
class VolumeFilesThroughAServer(unittest.TestCase):
    """`distband query` reads the file on the client, uploads its voxels and sends spacing, origin and the label
    flags; one server and a coordinator over three replicas (tiles of 8^3 bricks) give compute's bytes."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.dir = cls.tmp.name
        cls.labels = label_volume((40, 36, 44), 6, seed=11)
        write_nifti(os.path.join(cls.dir, "labels.nii.gz"), cls.labels)
        write_nrrd(os.path.join(cls.dir, "labels.nrrd"), cls.labels)
        cls.servers = [ServerProcess() for _ in range(4)]
        peers = "ipv4:" + ",".join(s.target for s in cls.servers[1:])
        cls.coordinator = ServerProcess("--peers", peers, "--tile-voxels", "8192")

    @classmethod
    def tearDownClass(cls):
        cls.coordinator.stop()
        for s in cls.servers:
            s.stop()
        cls.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    def same_everywhere(self, name, volume, *flags):
        run("compute", "--volume", self.path(volume), "--out", self.path(name + "_compute.npy"), *flags)
        expected = np.load(self.path(name + "_compute.npy"))
        for where, server in (("one server", self.servers[0]), ("a coordinator", self.coordinator)):
            run("query", "--server", server.target, "--progress", "quiet", "--volume", self.path(volume), "--out",
                self.path(f"{name}_{server.port}.npy"), *flags)
            np.testing.assert_array_equal(np.load(self.path(f"{name}_{server.port}.npy")), expected,
                                          err_msg=f"{name} through {where}")
        return expected

    def test_anisotropic_seed_field(self):
        field = self.same_everywhere("seed", "labels.nrrd")
        exact = ndimage.distance_transform_edt(self.labels == 0, sampling=float32_spacing_zyx())
        self.assertLessEqual(rel_err(field, exact), 1e-5)

    def test_multi_label_edt_with_black_border_unlimited_and_limited(self):
        exact = multi_label_edt(self.labels, float32_spacing_zyx(), True)
        field = self.same_everywhere("ml", "labels.nii.gz", "--labels", "--black-border")
        self.assertLessEqual(rel_err(field, exact), 1e-5)
        limited = self.same_everywhere("ml_limit", "labels.nii.gz", "--labels", "--black-border", "--limit", "1.5")
        inside = exact <= 1.5
        self.assertLessEqual(rel_err(limited[inside], exact[inside]), 1e-5)

    def test_multi_label_edt_without_black_border_limited(self):
        exact = multi_label_edt(self.labels, float32_spacing_zyx(), False)
        limited = self.same_everywhere("ml_open", "labels.nrrd", "--labels", "--limit", "3")
        inside = exact <= 3
        self.assertLessEqual(rel_err(limited[inside], exact[inside]), 1e-5)

    def test_an_uploaded_file_with_the_spacing_and_origin_upload_prints(self):
        up = subprocess.run([CLI, "upload", "--server", self.servers[0].target, "--volume", self.path("labels.nrrd")],
                            capture_output=True, text=True, check=True)
        asset = up.stdout.split()[0]
        hint = re.search(r"--asset (\S+) (--spacing \S+) (--origin \S+)", up.stderr)
        self.assertIsNotNone(hint, up.stderr)
        self.assertEqual(hint.group(1), asset)
        run("compute", "--volume", self.path("labels.nrrd"), "--labels", "--out", self.path("asset_compute.npy"))
        run("query", "--server", self.servers[0].target, "--progress", "quiet", "--asset", asset, "--labels",
            *hint.group(2).split(), *hint.group(3).split(), "--out", self.path("asset_query.npy"))
        np.testing.assert_array_equal(np.load(self.path("asset_query.npy")), np.load(self.path("asset_compute.npy")))

    def test_nearest_labels_and_the_nifti_output(self):
        run("compute", "--volume", self.path("labels.nii.gz"), "--out", self.path("nl_field.nii.gz"),
            "--nearest-label", self.path("nl_compute.npy"))
        expected = np.load(self.path("nl_compute.npy"))
        run("query", "--server", self.servers[0].target, "--progress", "quiet", "--volume",
            self.path("labels.nii.gz"), "--out", self.path("nl_query.nii.gz"), "--nearest-label",
            self.path("nl_query.npy"))
        np.testing.assert_array_equal(np.load(self.path("nl_query.npy")), expected)
        a, b = nib.load(self.path("nl_field.nii.gz")), nib.load(self.path("nl_query.nii.gz"))
        np.testing.assert_array_equal(a.affine, b.affine)
        np.testing.assert_array_equal(np.asarray(a.dataobj), np.asarray(b.dataobj))


if __name__ == "__main__":
    unittest.main(verbosity=2)
