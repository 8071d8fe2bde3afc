"""Shared fixtures: the repository's data and the `mss` binary."""

import os
import pathlib
import shutil
import sys
import subprocess

import pytest

import hexmss

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO / "data"


@pytest.fixture(autouse=True)
def default_threads():
    """Every test starts on the default pool."""
    hexmss.set_threads(None)
    yield
    hexmss.set_threads(None)


@pytest.fixture(scope="session")
def mss_binary():
    """The `mss` CLI of this checkout: $MSS_BIN, else target/release/mss,
    built if missing."""
    given = os.environ.get("MSS_BIN")
    if given:
        return pathlib.Path(given)
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    if not target.is_absolute():
        target = REPO / target
    path = target / "release" / "mss"
    if not path.exists():
        cargo = shutil.which("cargo")
        if cargo is None:
            pytest.skip("no mss binary and no cargo to build it")
        # Said on the terminal, not captured: a first build takes minutes.
        sys.__stderr__.write(
            f"\nbuilding the mss CLI into {target} (cargo build --release -p mss-cli; "
            "minutes on a first build; set MSS_BIN to use a built one)\n"
        )
        subprocess.run(
            [cargo, "build", "--release", "-p", "mss-cli"], cwd=REPO, check=True
        )
    return path


def small_scene(**overrides):
    """A small, quick scene as a dict: the critter at 10 cells sagging."""
    scene = {
        "mesh": {"path": "builtin:critter"},
        "voxelize": {"cells": 10},
        "material": {"young": 2.0e4, "poisson": 0.3, "density": 1000.0},
        "model": {"parameterization": "volumetric-barrier+hg"},
        "fixed": [{"kind": "lowest_layer"}],
        "loads": {"gravity": [0.0, 0.0, -9.81]},
        "solver": {"kind": "explicit", "damping": 8.0, "duration": 0.1},
        "output": {"every_time": 0.05},
    }
    for table, values in overrides.items():
        if isinstance(values, dict) and isinstance(scene.get(table), dict):
            scene[table] = {**scene[table], **values}
        else:
            scene[table] = values
    return scene
