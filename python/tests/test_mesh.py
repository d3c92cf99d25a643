"""Mesh files and sets: load_set, MeshSet, load_mesh, save_obj, save_glb."""

import numpy as np
import pytest

import meshvae


def test_version_is_the_workspace_version():
    import re
    from pathlib import Path

    cargo = (Path(__file__).resolve().parents[2] / "Cargo.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', cargo, re.M).group(1)
    assert meshvae.__version__ == version


def test_horse_gallop_loads_in_file_order(horse, horse_path):
    assert horse.positions.shape == (48, 8431, 3)
    assert horse.positions.dtype == np.float32
    assert horse.faces.shape == (16843, 3) and horse.faces.dtype == np.int32
    assert len(horse) == 48 and horse.vertex_count == 8431
    assert horse.names[:3] == ["0001", "0002", "0003"]
    assert horse.labels is None
    # Vertex order is the file's: frame 0 equals the first file read on its own.
    vertices, faces = meshvae.load_mesh(horse_path / "0001.obj")
    np.testing.assert_array_equal(vertices, horse.positions[0])
    np.testing.assert_array_equal(faces, horse.faces)
    # The arrays mirror the Rust set: read-only, and the same object on every access.
    assert not horse.positions.flags.writeable
    assert horse.positions is horse.positions


def test_obj_round_trip_is_bit_exact(tmp_path, sphere):
    vertices, faces = sphere
    vertices = vertices * np.float32(1.0 / 3.0)  # values with long decimal expansions
    meshvae.save_obj(tmp_path / "s.obj", vertices, faces.astype(np.int64))
    v, f = meshvae.load_mesh(tmp_path / "s.obj")
    np.testing.assert_array_equal(v, vertices)
    np.testing.assert_array_equal(f, faces)


def test_glb_frames_are_morph_targets_that_load_back_as_a_set(tmp_path, sphere_set):
    path = tmp_path / "anim.glb"
    meshvae.save_glb(path, sphere_set.positions, sphere_set.faces, names=list("abcde"))
    back = meshvae.load_set(path)
    assert len(back) == 5 and back.names == list("abcde")
    np.testing.assert_allclose(back.positions, sphere_set.positions, atol=1e-6)
    np.testing.assert_array_equal(back.faces, sphere_set.faces)


def test_mesh_set_from_arrays(sphere):
    vertices, faces = sphere
    frames = np.stack([vertices, 2 * vertices]).astype(np.float64)  # float64 is accepted
    s = meshvae.MeshSet(frames, faces, labels=["small", "big"])
    assert s.names == ["0", "1"] and s.labels == ["small", "big"]
    assert s.positions.dtype == np.float32
    assert "2 frames" in repr(s)
    with pytest.raises(meshvae.InputError, match="labels"):
        meshvae.MeshSet(frames, faces, labels=["one"])


def test_load_warnings_are_python_warnings(tmp_path):
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    with pytest.warns(UserWarning, match="1 quads split into triangles"):
        vertices, faces = meshvae.load_mesh(tmp_path / "quad.obj")
    assert vertices.shape == (4, 3) and faces.shape == (2, 3)
