"""Levels, Laplacians and pooling operators as scipy matrices."""

import numpy as np
import pytest
import scipy.sparse

import meshvae


@pytest.fixture(scope="module")
def horse_hierarchy(horse):
    return meshvae.Hierarchy.build(horse.positions[0], horse.faces, levels=1, pool="mean")


def test_horse_pooling_matrix(horse_hierarchy):
    assert horse_hierarchy.vertex_counts == [8431, 4216] and horse_hierarchy.levels == 1
    p = horse_hierarchy.pooling(0)
    assert isinstance(p, scipy.sparse.csr_matrix) and p.dtype == np.float32
    assert p.shape == (4216, 8431) and p.nnz == 8431  # each fine vertex in one cluster
    np.testing.assert_allclose(np.asarray(p.sum(axis=1)).ravel(), 1.0, rtol=1e-6)
    d = horse_hierarchy.depooling(0)
    assert d.shape == (8431, 4216)
    np.testing.assert_allclose((p @ d).toarray(), np.eye(4216), atol=1e-6)  # copy de-pooling
    # Row c of P averages exactly the members of cluster c.
    cluster = horse_hierarchy.cluster(0)
    rows, cols = p.nonzero()
    np.testing.assert_array_equal(cluster[cols], rows)


def test_matrices_in_float64_are_the_float32_ones_unrounded(horse_hierarchy):
    for get in (horse_hierarchy.laplacian, horse_hierarchy.pooling, horse_hierarchy.depooling):
        narrow, wide = get(0), get(0, dtype="float64")
        assert narrow.dtype == np.float32 and wide.dtype == np.float64, get
        assert get(0, dtype="float32").dtype == np.float32
        np.testing.assert_array_equal(narrow.indices, wide.indices)
        np.testing.assert_array_equal(narrow.data, wide.data.astype(np.float32))
    # 1/3 and its kin: the Laplacian holds values float32 cannot keep.
    lap = horse_hierarchy.laplacian(0, dtype="float64")
    assert (lap.data != lap.data.astype(np.float32)).any()
    with pytest.raises(meshvae.InputError, match="dtype"):
        horse_hierarchy.laplacian(0, dtype="float16")


def test_horse_scipy_pooling_equals_the_rust_pooling(horse_hierarchy, horse_features):
    x = horse_features[:6]  # [6, 8431, 9] raw ACAP features
    ours = horse_hierarchy.pool(0, x)
    assert ours.shape == (6, 4216, 9) and ours.dtype == np.float32
    p = horse_hierarchy.pooling(0)
    scale = np.abs(x).max()
    for i in range(len(x)):
        np.testing.assert_allclose(p @ x[i], ours[i], rtol=0, atol=1e-6 * scale)
    back = horse_hierarchy.depool(0, ours)
    np.testing.assert_allclose(back[0], horse_hierarchy.depooling(0) @ ours[0], rtol=1e-6)
    np.testing.assert_array_equal(back[0], ours[0][horse_hierarchy.cluster(0)])


def test_horse_laplacians(horse_hierarchy):
    for level, n in enumerate(horse_hierarchy.vertex_counts):
        lap = horse_hierarchy.laplacian(level)
        assert lap.shape == (n, n) and lap.dtype == np.float32
        np.testing.assert_allclose((lap - lap.T).toarray(), 0, atol=1e-6)
        # L̃ = L − I for λmax = 2: the diagonal of the normalised Laplacian (1) minus 1.
        np.testing.assert_allclose(lap.diagonal(), 0, atol=1e-6)


def test_two_levels_save_and_load(tmp_path, sphere):
    vertices, faces = sphere
    h = meshvae.Hierarchy.build(vertices, faces, levels=2, pool="qem", depool="transpose")
    assert h.vertex_counts == [len(vertices), (len(vertices) + 1) // 2, (len(vertices) + 3) // 4]
    assert h.pool_kind == "qem"
    # Transpose de-pooling is Pᵀ, as the authors' code.
    np.testing.assert_allclose(h.depooling(1).toarray(), h.pooling(1).T.toarray())
    h.save(tmp_path / "h.json")
    back = meshvae.Hierarchy.load(tmp_path / "h.json")
    assert back.vertex_counts == h.vertex_counts
    for step in range(2):
        assert (back.pooling(step) != h.pooling(step)).nnz == 0
        assert (back.laplacian(step + 1) != h.laplacian(step + 1)).nnz == 0


def test_poolers(sphere):
    vertices, faces = sphere
    x = np.random.default_rng(0).normal(size=(len(vertices), 4)).astype(np.float32)
    for pool in ("mean", "ours", "qem", "max", "sampling", "none", "graph", "remesh"):
        h = meshvae.Hierarchy.build(vertices, faces, pool=pool)
        m = h.vertex_counts[1]
        assert h.pooling(0).shape == (m, len(vertices)), pool
        y = h.pool(0, x)
        assert y.shape == (m, 4) and h.depool(0, y).shape == x.shape, pool
        assert (h.cluster(0) is None) == (pool in ("sampling", "none")), pool
    # Max pooling keeps the signed largest magnitude of each cluster.
    h = meshvae.Hierarchy.build(vertices, faces, pool="max")
    c = h.cluster(0)
    y = h.pool(0, x)
    for k in range(0, h.vertex_counts[1], 7):
        members = x[c == k, 1]
        assert y[k, 1] == members[np.argmax(np.abs(members))]


def test_bad_arguments(sphere, tmp_path):
    vertices, faces = sphere
    with pytest.raises(meshvae.InputError, match="unknown pooler"):
        meshvae.Hierarchy.build(vertices, faces, pool="average")
    h = meshvae.Hierarchy.build(vertices, faces)
    with pytest.raises(meshvae.InputError, match="step: 1 is not a pooling step"):
        h.pooling(1)
    with pytest.raises(meshvae.InputError, match="level: 2 is not a level"):
        h.laplacian(2)
    with pytest.raises(meshvae.InputError, match=r"x: expected shape \[\d+, C\]"):
        h.pool(0, np.zeros((10, 3), np.float32))
    with pytest.raises(meshvae.FileError, match="not a valid hierarchy file"):
        meshvae.Hierarchy.load(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    with pytest.raises(OSError, match="bad.json"):
        meshvae.Hierarchy.load(tmp_path / "bad.json")
