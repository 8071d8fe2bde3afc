"""Label images: read as nibabel and pynrrd read them (their readings are
kept in data/images/fixtures/expected.json), resampled to cubes with a label
per cell, and run as scenes with a material per label."""

import json

import numpy as np
import pytest

import hexmss
from conftest import DATA

FIXTURES = DATA / "images" / "fixtures"


def expected():
    return json.loads((FIXTURES / "expected.json").read_text())


def test_load_image_gives_labels_and_transform_as_the_writers_meant():
    for entry in expected():
        image = hexmss.load_image(FIXTURES / entry["file"])
        assert image.shape == tuple(entry["dims"])
        labels = image.labels
        assert labels.dtype == np.int32 and labels.shape == tuple(entry["dims"])
        assert not labels.flags.writeable
        counts = {int(k): v for k, v in entry["counts"].items()}
        assert image.label_counts() == counts
        for probe in entry["probes"]:
            i, j, k = probe["index"]
            assert labels[i, j, k] == probe["label"]
            world = image.affine @ np.array([i, j, k, 1.0])
            np.testing.assert_allclose(world[:3], probe["world"], rtol=1e-5, atol=1e-5)


def test_voxelize_image_keeps_the_chosen_labels_and_gives_each_cell_one():
    path = DATA / "images" / "organ.nii.gz"
    body = hexmss.voxelize_image(path, labels=[1, 2], cells=16)
    labels = body.cell_labels
    assert labels.shape == (body.lattice.num_cells,)
    assert set(np.unique(labels)) == {1, 2}
    assert set(body.voxels_per_label) == {1, 2}
    # The surface bounds the labelled voxels: the lattice's volume is close.
    lattice_volume = body.lattice.num_cells * body.lattice.h**3
    assert abs(lattice_volume - body.surface.volume) < 0.1 * body.surface.volume
    with pytest.raises(hexmss.VoxelizeError, match="threshold="):
        hexmss.voxelize_image(path, rule="any")
    with pytest.raises(hexmss.VoxelizeError, match=r"labels \[9\]"):
        hexmss.voxelize_image(path, labels=[9])
    with pytest.raises(hexmss.MeshError, match="gone.nii"):
        hexmss.voxelize_image(DATA / "images" / "gone.nii")


def test_the_organ_scene_runs_with_a_stiffer_nodule(tmp_path):
    text = (DATA / "scenes" / "organ.toml").read_text()
    text = text.replace("../images/organ.nii.gz", str(DATA / "images" / "organ.nii.gz"))
    text = text.replace("duration = 0.6", "duration = 0.05").replace("cells = 20", "cells = 10")
    scene = tmp_path / "organ.toml"
    scene.write_text(text)
    summary = hexmss.run(scene, tmp_path / "out")
    assert summary["bodies"][0]["cells"] > 50
    frame = (tmp_path / "out" / "lattice_0001.vtu").read_text()
    assert 'Name="label"' in frame
