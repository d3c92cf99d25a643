"""meshvae.sampling: CoMA / SpiralNet++ transform matrices and SpiralNet++'s transform.pkl, on
horse-gallop (skipped, saying so, where absent) and on a generated sphere."""

import math
import os
import pickle
import types

import numpy as np
import pytest
import scipy.sparse

import meshvae
from conftest import uv_sphere
from meshvae import sampling

FACTORS = [4, 4, 4, 4]


@pytest.fixture(scope="module", params=["sphere", "horse"])
def case(request):
    """(name, vertices, faces, SpiralNet++'s (M, A, D, U, F, V) for factors [4, 4, 4, 4])."""
    if request.param == "horse":
        horse = request.getfixturevalue("horse")  # skips where the data set is absent
        vertices, faces = horse.positions[0], horse.faces
    else:
        vertices, faces = uv_sphere(rings=40, segments=48)  # 1874 vertices
    result = sampling.generate_transform_matrices(vertices, faces, FACTORS)
    return request.param, vertices, faces, result


def diagonal(v):
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


def edge_counts(faces):
    """{(a, b) with a < b: number of faces on edge ab}."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    return {tuple(map(int, k)): int(c) for k, c in zip(edges, counts)}


def closest_distances(points, triangles):
    """Brute force: each point's distance to the closest of all triangles [T, 3, 3]."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    best = np.empty(len(points))
    for s in range(0, len(points), 128):
        p = points[s : s + 128, None, :]
        ab, ac, bc = b - a, c - a, c - b
        ap, bp, cp = p - a, p - b, p - c
        d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
        d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
        d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        with np.errstate(all="ignore"):
            denom = va + vb + vc
            face = a + ab * (vb / denom)[..., None] + ac * (vc / denom)[..., None]
            inside = (va >= 0) & (vb >= 0) & (vc >= 0) & (denom > 0)
            candidates = [np.where(inside, ((p - face) ** 2).sum(-1), np.inf)]
            for start, edge in ((a, ab), (a, ac), (b, bc)):
                t = np.clip(((p - start) * edge).sum(-1) / (edge * edge).sum(-1), 0, 1)
                q = start + edge * np.nan_to_num(t)[..., None]
                candidates.append(((p - q) ** 2).sum(-1))
        best[s : s + 128] = np.sqrt(np.min(np.min(candidates, axis=0), axis=1))
    return best


def test_vertex_counts_follow_the_references(case):
    name, vertices, _, (M, A, D, U, F, V) = case
    counts = [len(v) for v in V]
    expected = [len(vertices)]
    for f in FACTORS:
        expected.append(math.ceil(expected[-1] * (1.0 / f)))  # qslim_decimator_transformer's
    assert counts == expected == sampling.vertex_counts(len(vertices), FACTORS)
    if name == "horse":
        assert counts == [8431, 2108, 527, 132, 33]
    assert [len(m.v) for m in M] == counts and [len(f) for f in F] == [len(m.f) for m in M]
    assert len(A) == len(F) == len(V) == 5 and len(D) == len(U) == 4
    assert sampling.vertex_counts(10, [3, 1, 1.5]) == [10, 4, 4, 3]


def test_types_and_shapes(case):
    _, vertices, faces, (M, A, D, U, F, V) = case
    assert all(isinstance(m, sampling.Mesh) for m in M)
    assert all(m.v is v and m.f is f for m, v, f in zip(M, V, F))
    np.testing.assert_array_equal(V[0], vertices.astype(np.float64))
    np.testing.assert_array_equal(F[0], faces)
    for i, (v, f) in enumerate(zip(V, F)):
        assert v.dtype == np.float64 and v.shape == (len(v), 3)
        assert f.dtype == np.int64 and f.shape[1] == 3 and f.min() >= 0 and f.max() < len(v)
        assert len(np.unique(f)) == len(v), f"level {i}: every vertex on a face"
    for matrices in (A, D, U):
        for m in matrices:
            assert isinstance(m, scipy.sparse.csc_matrix) and m.dtype == np.float32
    counts = [len(v) for v in V]
    for i in range(4):
        assert A[i].shape == (counts[i], counts[i])
        assert D[i].shape == (counts[i + 1], counts[i])
        assert U[i].shape == (counts[i], counts[i + 1])


def test_adjacency_is_psbody_connectivity(case):
    """get_vert_connectivity: symmetric, zero diagonal, (a, b) = number of faces on edge ab."""
    name, _, _, (M, A, D, U, F, V) = case
    for a, f in zip(A, F):
        coo = a.tocoo()
        assert (a != a.T).nnz == 0 and not a.diagonal().any()
        counts = edge_counts(f)
        assert coo.nnz == 2 * len(counts)
        for r, c, value in zip(coo.row, coo.col, coo.data):
            assert value == counts[(min(r, c), max(r, c))]
    if name == "horse":  # one hole: its 19 boundary edges count 1, every other edge 2
        assert np.count_nonzero(A[0].data == 1) == 2 * 19
    else:  # closed
        assert all((a.data == 2).all() for a in A)


def test_down_sampling_selects_survivors(case):
    _, _, _, (M, A, D, U, F, V) = case
    for i, d in enumerate(D):
        r = d.tocsr()
        assert (np.diff(r.indptr) == 1).all(), f"level {i}: one entry per row"
        assert (r.data == 1).all()
        assert (np.diff(r.indices) > 0).all(), "survivors in ascending order"
        np.testing.assert_array_equal(d @ V[i], V[i + 1])  # CoMA: new_mesh_v = D · v


def test_up_sampling_is_barycentric_on_a_coarse_triangle(case):
    _, _, _, (M, A, D, U, F, V) = case
    for i, u in enumerate(U):
        r = u.tocsr()
        assert (np.diff(r.indptr) == 3).all(), f"level {i}: three weights per row"
        assert (r.data >= 0).all()
        np.testing.assert_allclose(np.asarray(r.sum(axis=1)).ravel(), 1.0, atol=1e-6)
        triangles = {tuple(sorted(t)) for t in F[i + 1].tolist()}
        corners = np.sort(r.indices.reshape(-1, 3), axis=1)
        assert all(tuple(t) in triangles for t in corners.tolist())


def test_up_sampled_points_are_the_closest_on_the_coarse_surface(case):
    """Each row of U puts its fine vertex at the closest point of the whole coarse surface (as
    CoMA's AABB-tree query), checked by brute force over all coarse triangles."""
    name, _, _, (M, A, D, U, F, V) = case
    for i in range(1 if name == "horse" else 0, 4):  # horse level 0: 35M pairs, too slow here
        q = U[i].astype(np.float64) @ V[i + 1]
        ours = np.linalg.norm(q - V[i], axis=1)
        best = closest_distances(V[i], V[i + 1][F[i + 1]])
        assert (ours <= best + 1e-6 * diagonal(V[0])).all(), f"level {i}"


def test_up_down_reproduces_linear_functions_on_the_coarse_surface(case):
    """x linear in position at level i: U @ (D @ x) is exactly that function at the up-sampled
    points U @ V[i + 1] (barycentric weights reproduce linear functions)."""
    _, _, _, (M, A, D, U, F, V) = case
    rng = np.random.default_rng(0)
    scale = diagonal(V[0])
    for i in range(4):
        g = rng.normal(size=(3, 4))
        x = V[i] @ g + 0.25 * scale
        y = U[i] @ (D[i] @ x)
        on_surface = (U[i].astype(np.float64) @ V[i + 1]) @ g + 0.25 * scale
        np.testing.assert_allclose(y, on_surface, rtol=0, atol=1e-5 * scale * np.abs(g).max())


def up_down_errors(V, D, U):
    """Per level: max over vertices and unit directions g of |U D x - x| / diagonal, x = V g."""
    scale = diagonal(V[0])
    directions = np.vstack([np.eye(3), np.random.default_rng(1).normal(size=(5, 3))])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return [
        float(np.abs(U[i] @ (D[i] @ (V[i] @ directions.T)) - V[i] @ directions.T).max() / scale)
        for i in range(len(D))
    ]


@pytest.mark.xfail(
    strict=True,
    reason="measured on horse-gallop [4, 4, 4, 4]: max |U D x - x| = 9.6e-3, 1.3e-2, 4.9e-2, "
    "1.2e-1 of the bounding-box diagonal per level. It is bounded by the fine vertices' distance "
    "to the 4x-decimated surface (max 1.0e-2, 1.4e-2, 5.3e-2, 1.2e-1; mean 6.2e-4, 1.8e-3, "
    "5.6e-3, 2.0e-2), as for any selection + barycentric up-sampling, CoMA's included",
)
def test_horse_up_down_within_a_thousandth_of_the_diagonal(horse):
    vertices, faces = horse.positions[0], horse.faces
    M, A, D, U, F, V = sampling.generate_transform_matrices(vertices, faces, FACTORS)
    errors = up_down_errors(V, D, U)
    assert max(errors) <= 1e-3, errors


def test_horse_up_down_error_is_the_distance_to_the_coarse_surface(horse):
    """The error of U D on linear functions (unit gradient) is no more than the fine vertex's
    distance to the coarse surface: the bound behind the figures of the xfail above."""
    vertices, faces = horse.positions[0], horse.faces
    M, A, D, U, F, V = sampling.generate_transform_matrices(vertices, faces, FACTORS)
    scale = diagonal(V[0])
    errors = up_down_errors(V, D, U)
    distances = [
        float(np.linalg.norm(U[i].astype(np.float64) @ V[i + 1] - V[i], axis=1).max()) / scale
        for i in range(4)
    ]
    assert all(e <= d + 1e-6 for e, d in zip(errors, distances)), (errors, distances)


def test_calling_forms(case):
    """(mesh, factors) with a psbody-like object, and the CoMA / Neural3DMM return forms."""
    _, vertices, faces, (M, A, D, U, F, V) = case
    psbody_like = types.SimpleNamespace(v=vertices.astype(np.float64), f=faces.astype(np.uint32))
    for mesh in (psbody_like, sampling.Mesh(vertices, faces)):
        M2, A2, D2, U2, F2, V2 = sampling.generate_transform_matrices(mesh, FACTORS)
        assert all(np.array_equal(a, b) for a, b in zip(V, V2))
        assert all((a != b).nnz == 0 for a, b in zip(U, U2))
    coma = sampling.generate_transform_matrices(vertices, faces, FACTORS, form="coma")
    assert len(coma) == 4
    for ours, theirs in zip(coma[1:], (A, D, U)):
        assert all(isinstance(m, scipy.sparse.csc_matrix) and m.dtype == np.float64 for m in ours)
        assert all(abs(a - b).max() < 1e-6 for a, b in zip(ours, theirs))
    n3 = sampling.generate_transform_matrices(vertices, faces, FACTORS, form="neural3dmm")
    assert len(n3) == 5 and len(n3[4]) == 4  # F: the coarse levels only, as Neural3DMM's
    assert all(np.array_equal(a, b) for a, b in zip(n3[4], F[1:]))


def test_factor_one_is_an_identity_level(sphere):
    vertices, faces = sphere
    M, A, D, U, F, V = sampling.generate_transform_matrices(vertices, faces, [1, 2])
    n = len(vertices)
    assert [len(v) for v in V] == [n, n, math.ceil(n / 2)]
    identity = scipy.sparse.identity(n)
    assert (D[0] != identity).nnz == 0 and (U[0] != identity).nnz == 0
    np.testing.assert_array_equal(F[1], F[0])


def test_edge_contraction_matrices_are_the_hierarchy_operators(sphere):
    vertices, faces = sphere
    M, A, D, U, F, V = sampling.edge_contraction_matrices(vertices, faces, [2, 2])
    h = meshvae.Hierarchy.build(vertices, faces, levels=2, pool="mean", ratio=0.5)
    assert [len(v) for v in V] == h.vertex_counts
    for i in range(2):
        assert abs(D[i] - h.pooling(i)).max() == 0 and abs(U[i] - h.depooling(i)).max() == 0
        np.testing.assert_array_equal(V[i + 1], h.positions(i + 1))
        np.testing.assert_array_equal(F[i + 1], h.faces(i + 1))
        np.testing.assert_allclose((D[i] @ U[i]).toarray(), np.eye(len(V[i + 1])), atol=1e-6)
    M, A, D, U = sampling.edge_contraction_matrices(
        vertices, faces, [2], pool="qem", depool="transpose", form="coma"
    )
    assert D[0].dtype == np.float64 and abs(U[0] - D[0].T).max() == 0


def test_save_transform_round_trip(case, tmp_path):
    _, _, _, result = case
    M, A, D, U, F, V = result
    path = tmp_path / "transform.pkl"
    path.write_bytes(b"an older file")  # replaced whole
    sampling.save_transform(path, result)
    with open(path, "rb") as fp:  # as SpiralNet++'s reconstruction/main.py reads it
        tmp = pickle.load(fp, encoding="latin1")
    assert sorted(tmp) == sorted(["vertices", "face", "adj", "down_transform", "up_transform"])
    assert all(isinstance(tmp[k], list) for k in tmp)
    for ours, theirs in zip(tmp["vertices"], V):
        assert isinstance(ours, np.ndarray) and np.array_equal(ours, theirs)
    for ours, theirs in zip(tmp["face"], F):
        assert isinstance(ours, np.ndarray) and np.array_equal(ours, theirs)
    for key, mats in (("adj", A), ("down_transform", D), ("up_transform", U)):
        assert len(tmp[key]) == len(mats)
        for ours, theirs in zip(tmp[key], mats):
            assert isinstance(ours, scipy.sparse.csc_matrix) and ours.dtype == np.float32
            assert (ours != theirs).nnz == 0
    assert os.listdir(tmp_path) == ["transform.pkl"]  # no temporary file left
    assert (path.stat().st_mode & 0o777) == 0o666 & ~_umask()
    # The keyword form (SpiralNet++'s dict) and the CoMA form (vertices, faces from M) agree.
    for i, call in enumerate(
        (
            dict(vertices=V, face=F, adj=A, down_transform=D, up_transform=U),
            dict(transform=(M, A, D, U)),
        )
    ):
        other = tmp_path / f"other{i}.pkl"
        sampling.save_transform(other, **call)
        with open(other, "rb") as fp:
            again = pickle.load(fp)
        assert all(np.array_equal(a, b) for a, b in zip(again["vertices"], V))
        assert all(np.array_equal(a, b) for a, b in zip(again["face"], F))
        assert all((a != b).nnz == 0 for a, b in zip(again["up_transform"], U))


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_bad_inputs(sphere, tmp_path):
    vertices, faces = sphere
    gen = sampling.generate_transform_matrices
    nan = vertices.copy()
    nan[5, 1] = np.nan
    with pytest.raises(meshvae.InputError, match="vertices: row 5 is not finite"):
        gen(nan, faces, [2])
    with pytest.raises(meshvae.InputError, match=r"vertices: expected an array of shape \[V, 3\]"):
        gen(vertices[:, :2], faces, [2])
    with pytest.raises(meshvae.InputError, match="vertices: expected a float array"):
        gen(np.zeros((10, 3), np.int32), faces, [2])
    with pytest.raises(meshvae.InputError, match="faces: expected an integer array"):
        gen(vertices, faces.astype(np.float32), [2])
    with pytest.raises(meshvae.InputError, match="faces: row 0 .* outside"):
        gen(vertices, faces + len(vertices), [2])
    for factor, message in (
        (0, "not a positive finite number"),
        (-4, "not a positive finite number"),
        (float("nan"), "not a positive finite number"),
        (0.5, "< 1 would ask for more vertices"),
        ("4", "expected a number"),
        (True, "expected a number"),
    ):
        with pytest.raises(meshvae.InputError, match=rf"factors\[1\]: .*{message}"):
            gen(vertices, faces, [2, factor])
    with pytest.raises(meshvae.InputError, match="level 4 would have 1 vertices"):
        gen(vertices, faces, [4, 4, 4, 4])  # 178 -> 45 -> 12 -> 3 -> 1
    with pytest.raises(meshvae.InputError, match="factors: expected a list"):
        gen(vertices, faces, 4)
    with pytest.raises(meshvae.InputError, match="form: unknown form 'pytorch'"):
        gen(vertices, faces, [2], form="pytorch")
    with pytest.raises(meshvae.InputError, match=r"with a mesh having \.v and \.f"):
        gen(vertices, [2])
    with pytest.raises(meshvae.InputError, match="not an edge-contraction pooler"):
        sampling.edge_contraction_matrices(vertices, faces, [2], pool="max")
    # A non-manifold input: a third triangle on one edge.
    extra = np.vstack([vertices, [[0.0, 0.0, 3.0]]]).astype(np.float32)
    a, b = faces[0, 0], faces[0, 1]
    with pytest.raises(meshvae.InputError, match="level 1"):
        gen(extra, np.vstack([faces, [[a, b, len(vertices)]]]), [2])
    # An unreachable count: a closed surface cannot shrink to 3 vertices.
    with pytest.raises(meshvae.InputError, match="level 3 .3 vertices"):
        gen(vertices, faces, [4, 4, 4])

    result = gen(vertices, faces, [2, 2])
    M, A, D, U, F, V = result
    save = sampling.save_transform
    with pytest.raises(meshvae.FileError, match="cannot write"):
        save(tmp_path / "missing" / "transform.pkl", result)
    with pytest.raises(meshvae.InputError, match="not both"):
        save(tmp_path / "t.pkl", result, adj=A)
    with pytest.raises(meshvae.InputError, match="missing vertices, face"):
        save(tmp_path / "t.pkl", adj=A, down_transform=D, up_transform=U)
    with pytest.raises(meshvae.InputError, match="expected 3 entries, got 2"):
        save(tmp_path / "t.pkl", vertices=V, face=F[:2], adj=A, down_transform=D, up_transform=U)
    with pytest.raises(meshvae.InputError, match=r"down_transform\[1\]: expected shape"):
        save(tmp_path / "t.pkl", (M, A, [D[0], D[0]], U, F, V))
    with pytest.raises(meshvae.InputError, match=r"up_transform\[0\]: expected a scipy.sparse"):
        save(tmp_path / "t.pkl", (M, A, D, [U[0].toarray(), U[1]], F, V))
    bad_v = [V[0].copy(), V[1], V[2]]
    bad_v[0][0, 0] = np.inf
    with pytest.raises(meshvae.InputError, match=r"vertices\[0\]: not finite"):
        save(tmp_path / "t.pkl", (M, A, D, U, F, bad_v))
    with pytest.raises(meshvae.InputError, match=r"expected \(M, A, D, U, F, V\)"):
        save(tmp_path / "t.pkl", (A, D))
    assert os.listdir(tmp_path) == []  # nothing written by a failed call
    assert issubclass(meshvae.InputError, ValueError) and issubclass(meshvae.FileError, OSError)
