"""Shared fixtures: the real data sets (skipped, saying so, when absent), a small synthetic
mesh that needs no data, and the `meshvae` command to compare against."""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import meshvae

REPO = Path(__file__).resolve().parents[2]


def datasets_root() -> Path:
    """$MESHVAE_DATASETS, else ../shared/datasets beside the repository (as the Rust tests)."""
    env = os.environ.get("MESHVAE_DATASETS")
    return Path(env) if env else REPO.parent / "shared" / "datasets"


def dataset(name: str) -> Path:
    path = datasets_root() / name
    if not (path.is_dir() and any(path.glob("*.obj"))):
        pytest.skip(
            f"SKIPPED: data set {name} not found in {datasets_root()} "
            "(run ../shared/datasets/unpack, or set MESHVAE_DATASETS)"
        )
    return path


@pytest.fixture(scope="session")
def horse_path() -> Path:
    return dataset("horse-gallop")


@pytest.fixture(scope="session")
def horse(horse_path) -> meshvae.MeshSet:
    return meshvae.load_set(horse_path)


@pytest.fixture(scope="session")
def horse_features(horse) -> np.ndarray:
    return meshvae.acap_features(horse)


@pytest.fixture(scope="session")
def cli() -> Path:
    """The `meshvae` command named by $MESHVAE_CLI (python/run-tests sets it to the binary
    `cargo test --workspace` built)."""
    path = os.environ.get("MESHVAE_CLI")
    if not path or not Path(path).is_file():
        pytest.skip(
            "SKIPPED: set MESHVAE_CLI to a meshvae binary to compare with the command line "
            "(python/run-tests does)"
        )
    return Path(path)


@pytest.fixture(scope="session")
def horse_model(cli, horse_path, tmp_path_factory) -> Path:
    """A horse-gallop model folder trained briefly by the command line (20 steps, far from
    trained: the tests compare code paths, not models). Read it; never write into it."""
    out = tmp_path_factory.mktemp("horse-model") / "model"
    run_cli(cli, "train", horse_path, "--out", out, "--steps", 20, "--quiet")
    return out


def run_cli(cli: Path, *args) -> str:
    done = subprocess.run(
        [str(cli), *map(str, args)], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def uv_sphere(rings: int = 12, segments: int = 16):
    """A closed triangle mesh (two poles, `rings - 1` latitude circles): float32 vertices,
    int32 faces."""
    vertices = [(0.0, 0.0, 1.0)]
    for i in range(1, rings):
        theta = np.pi * i / rings
        for j in range(segments):
            phi = 2 * np.pi * j / segments
            vertices.append(
                (np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta))
            )
    vertices.append((0.0, 0.0, -1.0))
    south = len(vertices) - 1

    def ring(i, j):
        return 1 + (i - 1) * segments + j % segments

    faces = []
    for j in range(segments):
        faces.append((0, ring(1, j), ring(1, j + 1)))
        faces.append((south, ring(rings - 1, j + 1), ring(rings - 1, j)))
    for i in range(1, rings - 1):
        for j in range(segments):
            a, b = ring(i, j), ring(i, j + 1)
            c, d = ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, c, b), (b, c, d)]
    return np.asarray(vertices, np.float32), np.asarray(faces, np.int32)


@pytest.fixture
def sphere():
    return uv_sphere()


@pytest.fixture
def sphere_set(sphere):
    """Five frames of the sphere: stretched along z and twisted a little more each frame."""
    vertices, faces = sphere
    frames = []
    for k in range(5):
        t = 0.1 * k
        z = vertices[:, 2]
        angle = t * z
        x = vertices[:, 0] * np.cos(angle) - vertices[:, 1] * np.sin(angle)
        y = vertices[:, 0] * np.sin(angle) + vertices[:, 1] * np.cos(angle)
        frames.append(np.stack([x, y, z * (1 + t)], axis=1))
    return meshvae.MeshSet(np.asarray(frames, np.float32), faces)
