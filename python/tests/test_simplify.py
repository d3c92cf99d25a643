"""The simplifier and its fine → coarse vertex map."""

import json

import numpy as np
import pytest

import meshvae
from conftest import run_cli

REPORT_KEYS = {
    "method", "vertices_in", "vertices_out", "faces_in", "faces_out", "lambda", "edge_cv_in",
    "edge_cv", "cluster_cv", "cluster_max", "cluster_area_cv", "manifold", "flipped_faces",
    "degenerate_faces", "euler_in", "euler_out", "seconds", "geometric_error_rel",
}


@pytest.fixture(scope="module")
def horse_simplified(horse):
    return meshvae.simplify(horse.positions[0], horse.faces)


def test_horse_cluster_map(horse_simplified):
    cluster = horse_simplified.cluster
    assert cluster.shape == (8431,) and cluster.dtype == np.int64
    assert cluster.min() == 0 and cluster.max() == 4215
    assert len(np.unique(cluster)) == 4216  # every coarse vertex has a cluster
    assert horse_simplified.vertices.shape == (4216, 3)
    # Coarse vertex k is the k-th surviving fine vertex, which is in its own cluster.
    survivors = horse_simplified.survivors
    assert np.all(np.diff(survivors) > 0)
    np.testing.assert_array_equal(cluster[survivors], np.arange(4216))


def test_horse_cluster_map_is_the_one_training_pools_over(horse, horse_simplified):
    # `meshvae train` pools over the clusters of mesh-hierarchy's build of the template.
    h = meshvae.Hierarchy.build(horse.positions[0], horse.faces, levels=1, pool="mean")
    np.testing.assert_array_equal(h.cluster(0), horse_simplified.cluster)
    np.testing.assert_array_equal(h.positions(1), horse_simplified.vertices)
    np.testing.assert_array_equal(h.faces(1), horse_simplified.faces)


def test_horse_equals_the_command_line(cli, horse_path, horse_simplified, tmp_path):
    out = tmp_path / "coarse.obj"
    report = json.loads(run_cli(cli, "simplify", horse_path, "--out", out, "--json"))
    vertices, faces = meshvae.load_mesh(out)  # OBJ coordinates read back bit-exactly
    np.testing.assert_array_equal(vertices, horse_simplified.vertices)
    np.testing.assert_array_equal(faces, horse_simplified.faces)
    ours = dict(horse_simplified.report)
    assert set(ours) == REPORT_KEYS == set(report)
    for key in ("seconds",):  # timings differ run to run
        ours.pop(key), report.pop(key)
    assert ours == report


def test_methods_on_a_sphere(sphere):
    vertices, faces = sphere
    n = len(vertices)
    for method, lam in (("modified-qem", 0.001), ("qem", 0.0), ("remesh", None)):
        s = meshvae.simplify(vertices, faces, ratio=0.5, method=method)
        assert len(s.vertices) == (n + 1) // 2, method
        assert s.cluster.shape == (n,) and s.cluster.max() == len(s.vertices) - 1
        assert s.report["lambda"] == lam and s.report["manifold"]
        assert (s.survivors is None) == (method == "remesh")
    custom = meshvae.simplify(vertices, faces, ratio=0.25, lam=0.01)
    assert custom.report["lambda"] == 0.01 and len(custom.vertices) == (n + 3) // 4


def test_bad_arguments(sphere):
    vertices, faces = sphere
    with pytest.raises(meshvae.InputError, match="method: unknown method"):
        meshvae.simplify(vertices, faces, method="fast")
    with pytest.raises(meshvae.InputError, match="lam"):
        meshvae.simplify(vertices, faces, method="remesh", lam=0.1)
    with pytest.raises(meshvae.InputError, match="lam"):
        meshvae.simplify(vertices, faces, method="qem", lam=0.1)
    with pytest.raises(ValueError, match="ratio: 1.5 is not in"):
        meshvae.simplify(vertices, faces, ratio=1.5)
