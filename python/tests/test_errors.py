"""Bad input raises meshvae.InputError (a ValueError) or meshvae.FileError (an OSError) with a
message naming the argument or file; nothing panics across the boundary."""

import numpy as np
import pytest

import meshvae


def test_error_classes():
    assert issubclass(meshvae.InputError, ValueError)
    assert issubclass(meshvae.FileError, OSError)
    for cls in (meshvae.InputError, meshvae.FileError):
        assert issubclass(cls, meshvae.MeshvaeError)


@pytest.mark.parametrize(
    "vertices, message",
    [
        (np.zeros((10, 4), np.float32), r"vertices: expected an array of shape \[V, 3\], got shape \[10, 4\]"),
        (np.zeros((2, 10, 3), np.float32), r"vertices: expected an array of shape \[V, 3\]"),
        (np.zeros((10, 3), np.int32), "vertices: expected a float32 or float64 array, got dtype int32"),
        ([[0, 1], [2]], "vertices: not convertible to an array"),
    ],
)
def test_wrong_vertex_arrays(sphere, vertices, message):
    _, faces = sphere
    with pytest.raises(meshvae.InputError, match=message):
        meshvae.simplify(vertices, faces)


def test_wrong_face_arrays(sphere):
    vertices, faces = sphere
    with pytest.raises(ValueError, match=r"faces: expected an array of shape \[F, 3\]"):
        meshvae.save_obj("never.obj", vertices, faces[:, :2])
    with pytest.raises(ValueError, match="faces: expected an integer array, got dtype float32"):
        meshvae.Hierarchy.build(vertices, faces.astype(np.float32))
    bad = faces.copy()
    bad[5, 1] = -1
    with pytest.raises(ValueError, match="faces: index -1 is not in"):
        meshvae.simplify(vertices, bad)


def test_faces_that_do_not_match_the_vertices(sphere):
    vertices, faces = sphere
    with pytest.raises(
        meshvae.InputError,
        match=rf"template_faces: row \d+ refers to vertex \d+, but template_vertices has {len(vertices) - 20} vertices",
    ):
        meshvae.reconstruct(np.zeros((len(vertices) - 20, 9)), vertices[:-20], faces)
    with pytest.raises(meshvae.InputError, match=rf"features: expected shape \[N, {len(vertices)}, 9\]"):
        meshvae.reconstruct(np.zeros((3, 100, 9)), vertices, faces)


def test_a_set_whose_files_disagree(tmp_path, sphere):
    vertices, faces = sphere
    meshvae.save_obj(tmp_path / "1.obj", vertices, faces)
    meshvae.save_obj(tmp_path / "2.obj", vertices, faces[::-1])
    with pytest.raises(meshvae.InputError, match="must share one connectivity"):
        meshvae.load_set(tmp_path)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(meshvae.FileError, match="missing.obj"):
        meshvae.load_mesh(tmp_path / "missing.obj")
    with pytest.raises(OSError, match="nowhere"):
        meshvae.load_set(tmp_path / "nowhere")
    with pytest.raises(OSError, match="missing.safetensors"):
        meshvae.load_features(tmp_path / "missing.safetensors")
    (tmp_path / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(meshvae.InputError, match="broken.obj"):
        meshvae.load_mesh(tmp_path / "broken.obj")
    with pytest.raises(OSError, match="no-such-folder"):
        meshvae.save_obj(
            tmp_path / "no-such-folder" / "x.obj",
            np.zeros((3, 3), np.float32),
            np.array([[0, 1, 2]]),
        )


def test_a_non_manifold_mesh(sphere):
    vertices, faces = sphere
    doubled = np.concatenate([faces, faces[:1]])  # one triangle twice
    with pytest.raises(meshvae.InputError, match="not a 2-manifold"):
        meshvae.simplify(vertices, doubled)


def test_meshvae_imports_without_torch_and_meshvae_torch_says_how_to_get_it():
    """`import meshvae` never needs torch; `import meshvae.torch` without it is an ImportError
    saying `pip install torch` (torch is hidden from a fresh interpreter, installed or not)."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import meshvae\n"
        "try:\n"
        "    import meshvae.torch\n"
        "except ImportError as e:\n"
        "    print('ImportError:', e)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "ImportError: meshvae.torch needs PyTorch" in done.stdout
    assert "pip install torch" in done.stdout
