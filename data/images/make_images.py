"""Writes the label images the project ships, with other tools' writers.

    python data/images/make_images.py   (needs numpy, nibabel, pynrrd)

- data/images/organ.nii.gz: the bundled example (data/scenes/organ.toml).
  A synthetic organ: an ellipsoid of tissue (label 1) holding a stiffer
  nodule (label 2), beside a bone (label 3) that is not part of the body;
  anisotropic voxels (1.5 x 1.5 x 3 mm) in an oblique orientation.
- data/images/fixtures/: small label volumes in every format, byte order
  and data type the readers must take (NIfTI-1 and -2, gzip or not, a
  .hdr/.img pair; NRRD raw, gzip and ascii, attached and detached), and
  expected.json: what nibabel and pynrrd say of each (dimensions, label
  counts, the world position of known voxels), for the Rust tests to
  compare with.

The output is deterministic: running the script again rewrites the same
labels and transforms (gzip timestamps aside).
"""

import json
import math
import os

import nibabel as nib
import nrrd
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FIXTURES = os.path.join(HERE, "fixtures")


def rotation(ax, ay, az):
    """Rotation about x, then y, then z (degrees)."""
    cx, sx = math.cos(math.radians(ax)), math.sin(math.radians(ax))
    cy, sy = math.cos(math.radians(ay)), math.sin(math.radians(ay))
    cz, sz = math.cos(math.radians(az)), math.sin(math.radians(az))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def oblique_affine(spacing, angles, origin):
    a = np.eye(4)
    a[:3, :3] = rotation(*angles) @ np.diag(spacing)
    a[:3, 3] = origin
    return a


def organ():
    spacing = (1.5, 1.5, 3.0)
    dims = (72, 56, 30)
    affine = oblique_affine(spacing, (8.0, -5.0, 20.0), (-40.0, -30.0, 10.0))
    labels = np.zeros(dims, dtype=np.uint8)
    idx = np.indices(dims).reshape(3, -1).T.astype(float)
    centre = np.array([(d - 1) / 2 for d in dims])
    # Positions in mm along the voxel axes, from the volume's centre.
    local = (idx - centre) * np.array(spacing)
    tissue = (local[:, 0] / 42) ** 2 + (local[:, 1] / 30) ** 2 + (local[:, 2] / 24) ** 2 <= 1
    nodule = np.sum((local - np.array([12.0, 4.0, 0.0])) ** 2, axis=1) <= 10.0**2
    bone = (np.abs(local[:, 0] + 40) <= 6) & (np.abs(local[:, 1]) <= 25) & (np.abs(local[:, 2] + 30) <= 8)
    flat = labels.reshape(-1, order="C")
    flat[tissue] = 1
    flat[nodule & tissue] = 2
    flat[bone & ~tissue] = 3
    labels = flat.reshape(dims, order="C")
    img = nib.Nifti1Image(labels, affine)
    img.header.set_xyzt_units("mm")
    img.set_qform(affine, code=1)
    img.set_sform(affine, code=1)
    nib.save(img, os.path.join(HERE, "organ.nii.gz"))


def fixture_labels(dtype):
    """A 7 x 5 x 4 volume: a block of label 1, a column of label 2, and one
    voxel with the type's largest (or smallest) value that fits a label."""
    dims = (7, 5, 4)
    labels = np.zeros(dims, dtype=dtype)
    labels[1:5, 1:4, 1:3] = 1
    labels[5, 0:5, 2] = 2
    info = np.iinfo(dtype)
    extreme = min(info.max, 2**31 - 1)
    if info.min < 0:
        extreme = max(info.min, -(2**31))
    labels[6, 4, 3] = extreme
    return labels


PROBES = [(0, 0, 0), (1, 2, 1), (5, 3, 2), (6, 4, 3)]


def expected_entry(path, labels, affine, space):
    counts = {}
    for v, n in zip(*np.unique(labels, return_counts=True)):
        counts[str(int(v))] = int(n)
    probes = []
    for p in PROBES:
        world = affine[:3, :3] @ np.array(p, dtype=float) + affine[:3, 3]
        probes.append({"index": list(p), "label": int(labels[p]), "world": [float(w) for w in world]})
    return {
        "file": os.path.relpath(path, FIXTURES),
        "dims": list(labels.shape),
        "counts": counts,
        "probes": probes,
        "space": space,
    }


def fixtures():
    os.makedirs(FIXTURES, exist_ok=True)
    expected = []
    affine = oblique_affine((0.5, 0.75, 2.0), (10.0, 20.0, 30.0), (12.5, -40.0, 7.25))
    for dtype in ["u1", "i2", "u2", "i4"]:
        for order in ["<", ">"]:
            dt = np.dtype(order + dtype)
            labels = fixture_labels(dt)
            tag = f"{dtype}_{'le' if order == '<' else 'be'}"
            # NIfTI-1 and NIfTI-2, plain and gzip, through nibabel.
            for version, cls, hdr_cls in [(1, nib.Nifti1Image, nib.Nifti1Header), (2, nib.Nifti2Image, nib.Nifti2Header)]:
                for ext in [".nii", ".nii.gz"]:
                    header = hdr_cls(endianness=order)
                    img = cls(labels, affine, header=header)
                    img.set_data_dtype(dt)
                    img.header.set_xyzt_units("mm")
                    path = os.path.join(FIXTURES, f"nifti{version}_{tag}{ext}")
                    nib.save(img, path)
                    back = nib.load(path)
                    expected.append(expected_entry(path, np.asarray(back.dataobj), back.affine, "RAS"))
            # NRRD raw and gzip, attached, and raw detached, through pynrrd.
            header = {
                "space": "left-posterior-superior",
                "space directions": affine[:3, :3].T,
                "space origin": affine[:3, 3],
                "endian": "little" if order == "<" else "big",
            }
            for encoding in ["raw", "gzip"]:
                path = os.path.join(FIXTURES, f"nrrd_{tag}_{encoding}.nrrd")
                nrrd.write(path, labels, dict(header, encoding=encoding), index_order="F")
                data, _ = nrrd.read(path, index_order="F")
                expected.append(expected_entry(path, data, affine, "LPS"))
            path = os.path.join(FIXTURES, f"nrrd_{tag}_detached.nhdr")
            nrrd.write(path, labels, dict(header, encoding="raw"), detached_header=True, index_order="F")
            data, _ = nrrd.read(path, index_order="F")
            expected.append(expected_entry(path, data, affine, "LPS"))
    # Text data, and a header with its own .img (NIfTI-1 pair), a qform only,
    # and neither transform (pixel sizes from the origin).
    labels = fixture_labels(np.dtype("<i2"))
    path = os.path.join(FIXTURES, "nrrd_ascii.nrrd")
    nrrd.write(path, labels, {"space": "right-anterior-superior", "space directions": affine[:3, :3].T, "space origin": affine[:3, 3], "encoding": "ascii"}, index_order="F")
    expected.append(expected_entry(path, labels, affine, "RAS"))
    pair = nib.Nifti1Pair(labels, affine)
    pair.header.set_xyzt_units("mm")
    path = os.path.join(FIXTURES, "nifti1_pair.hdr")
    nib.save(pair, path)
    expected.append(expected_entry(path, labels, nib.load(path).affine, "RAS"))
    rigid = oblique_affine((0.5, 0.75, 2.0), (10.0, 20.0, 30.0), (12.5, -40.0, 7.25))
    q = nib.Nifti1Image(labels, None)
    q.set_qform(rigid, code=1)
    q.set_sform(None, code=0)
    q.header.set_xyzt_units("mm")
    path = os.path.join(FIXTURES, "nifti1_qform_only.nii")
    nib.save(q, path)
    expected.append(expected_entry(path, labels, nib.load(path).header.get_qform(), "RAS"))
    plain = nib.Nifti1Image(labels, None)
    plain.header.set_zooms((0.5, 0.75, 2.0))
    plain.set_qform(None, code=0)
    plain.set_sform(None, code=0)
    path = os.path.join(FIXTURES, "nifti1_no_transform.nii")
    nib.save(plain, path)
    expected.append(expected_entry(path, labels, np.diag([0.5, 0.75, 2.0, 1.0]), "other"))
    with open(os.path.join(FIXTURES, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    organ()
    fixtures()
