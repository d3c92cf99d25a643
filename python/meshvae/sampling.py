"""CoMA / SpiralNet++ / Neural3DMM mesh sampling without psbody: the transform matrices of
``mesh_sampling.generate_transform_matrices`` and SpiralNet++'s ``transform.pkl``.

Those projects build their hierarchy with ``mesh_sampling.generate_transform_matrices(mesh,
[4, 4, 4, 4])``, which needs psbody-mesh (and, in CoMA, opendr) and a slow pure-Python
decimator. This module is a drop-in for it, computed by the Rust crates (qem-simplify's
classical QEM and mesh-hierarchy's CoMA up-sampling):

- :func:`generate_transform_matrices` -- SpiralNet++'s six lists ``(M, A, D, U, F, V)``
  (default), CoMA's four ``(M, A, D, U)`` (``form="coma"``) or Neural3DMM's five
  ``(M, A, D, U, F)`` (``form="neural3dmm"``);
- :func:`save_transform` -- the ``transform.pkl`` SpiralNet++'s ``reconstruction/main.py``
  loads (keys ``vertices``, ``face``, ``adj``, ``down_transform``, ``up_transform``), written
  atomically;
- :func:`edge_contraction_matrices` -- the same lists with meshvae's own edge-contraction mean
  pooling (the paper's simplifier) in place of CoMA's vertex selection, to try it in those
  networks unchanged.

Conventions followed (those of the references' ``mesh_sampling.py``):

- level ``i + 1`` has ``math.ceil(n_i * (1.0 / factor_i))`` vertices, the target of their
  ``qslim_decimator_transformer``, reached exactly;
- coarse vertex ``k`` is the ``k``-th surviving fine vertex in ascending index (their
  ``np.unique`` of the decimated faces), kept at its own position: ``V[i + 1] == D[i] @ V[i]``;
- ``D[i]`` (``n_{i+1} x n_i``) has one 1 per row, on the survivor; ``U[i]`` (``n_i x n_{i+1}``)
  has three stored entries per row, on the coarse triangle closest to the fine vertex;
- ``A[i]`` is psbody's ``get_vert_connectivity``: symmetric, zero diagonal, entry ``(a, b)`` the
  number of faces having edge ``ab`` (2 inside a closed surface, 1 on a boundary; not 0/1);
- matrices are ``scipy.sparse.csc_matrix``: float32 for SpiralNet++ (its ``.astype('float32')``),
  float64 for CoMA and Neural3DMM (which cast them themselves).

Where this differs from the references (each also noted at the function):

- *Decimation.* Our classical QEM (Garland-Heckbert, lambda = 0, as ``Hierarchy``'s
  ``sampling`` pooler) places each contraction at the quadric optimum and refuses contractions
  that would break the 2-manifold, flip or degenerate a face; theirs is a half-edge collapse
  with no such checks. So the *choice* of survivors differs (both keep the survivors at their
  original positions in the output), and the input must be a 2-manifold triangle mesh.
- *Up-sampling weights.* Ours are the barycentric coordinates of the closest point on the
  closest coarse triangle: three weights >= 0 summing to 1 in every row (an explicit 0 where
  the point is on an edge or corner). Theirs solve a least-squares system that gives the same
  weights when the closest point is inside the triangle, but on an edge they fit the *fine
  vertex itself* by the edge's two end points (weights that need not sum to 1).
- *Closest triangle.* As theirs (an AABB-tree query), the closest of all coarse triangles
  (mesh-hierarchy's ``sampling::upsampling_global``); ties may pick another triangle.
- *Meshes.* ``M`` holds :class:`Mesh` named tuples ``(v, f)``, not psbody meshes (no
  ``write_obj``: use :func:`meshvae.save_obj`); ``M[0]``, ``V[0]`` and ``F[0]`` are float64 /
  int64 copies of the input, not the input objects. ``V`` is float64, ``F`` int64 at every
  level.
- *Factors.* A factor below 1 (theirs: silently no decimation) or one that would leave fewer
  than 3 vertices is an :class:`~meshvae.InputError`; a factor of 1 is an identity level.
- *meshvae's own operators.* ``Hierarchy.build(..., pool="sampling")`` uses the same survivors
  but keeps the simplifier's (quadric-optimal) coarse positions, searches the closest triangle
  near the fine vertex's cluster only, and shrinks by one ``ratio`` per step; this module keeps
  the survivors' positions and searches all triangles, as CoMA.
"""

from __future__ import annotations

import math
import numbers
import os
import pickle
import secrets
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, Sequence, Union, overload

import numpy as np
import numpy.typing as npt

from . import _meshvae
from ._errors import FileError, InputError

if TYPE_CHECKING:
    import scipy.sparse

__all__ = [
    "Mesh",
    "edge_contraction_matrices",
    "generate_transform_matrices",
    "save_transform",
    "vertex_counts",
]

Form = Literal["spiralnet", "coma", "neural3dmm"]
_FORMS = ("spiralnet", "coma", "neural3dmm")

_Faces = npt.NDArray[np.int64]
_Vertices = npt.NDArray[np.float64]


class Mesh(NamedTuple):
    """One level: ``v`` float64 [V, 3] vertices, ``f`` int64 [F, 3] triangles (the attributes
    of a psbody ``Mesh`` that CoMA, SpiralNet++ and Neural3DMM read). Also accepted as the first
    argument of :func:`generate_transform_matrices`, as is any object with ``.v`` and ``.f``."""

    v: npt.NDArray[np.float64]
    f: npt.NDArray[np.int64]


#: SpiralNet++'s ``(M, A, D, U, F, V)``.
SpiralNetMatrices = tuple[
    list[Mesh],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
    list[_Faces],
    list[_Vertices],
]
#: CoMA's ``(M, A, D, U)``.
ComaMatrices = tuple[
    list[Mesh],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
]
#: Neural3DMM's ``(M, A, D, U, F)``, ``F`` of levels 1..=L.
Neural3dmmMatrices = tuple[
    list[Mesh],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
    list["scipy.sparse.csc_matrix"],
    list[_Faces],
]
Matrices = Union[SpiralNetMatrices, ComaMatrices, Neural3dmmMatrices]


def vertex_counts(vertex_count: int, factors: Sequence[float]) -> list[int]:
    """Vertex counts of levels 0..=L for ``factors``: ``n_{i+1} = ceil(n_i * (1.0 / f_i))``, the
    target of CoMA's and SpiralNet++'s ``qslim_decimator_transformer`` (same floating-point
    expression, so the same counts). Raises ``InputError`` for a factor that is not a finite
    number >= 1 or a level of fewer than 3 vertices."""
    if isinstance(factors, (str, bytes)) or not hasattr(factors, "__iter__"):
        raise InputError(f"factors: expected a list of numbers, got {type(factors).__name__}")
    counts = [int(vertex_count)]
    for i, f in enumerate(list(factors)):
        if isinstance(f, bool) or not isinstance(f, numbers.Real):
            raise InputError(f"factors[{i}]: expected a number, got {f!r}")
        f = float(f)
        if not math.isfinite(f) or f <= 0:
            raise InputError(f"factors[{i}]: {f} is not a positive finite number")
        if f < 1:
            raise InputError(
                f"factors[{i}]: {f} < 1 would ask for more vertices than level {i} has "
                "(each factor divides the vertex count)"
            )
        n = math.ceil(counts[-1] * (1.0 / f))
        if n < 3:
            raise InputError(
                f"factors: level {i + 1} would have {n} vertices ({counts[-1]} / {f} rounded "
                "up), fewer than the 3 of a triangle"
            )
        counts.append(n)
    return counts


def _mesh_arrays(
    mesh_or_vertices: Any, faces_or_factors: Any, factors: Any
) -> tuple[np.ndarray, np.ndarray, Any]:
    """(vertices float64 [V, 3], faces int64 [F, 3], factors) from either calling form."""
    if factors is None:
        mesh = mesh_or_vertices
        if not (hasattr(mesh, "v") and hasattr(mesh, "f")):
            raise InputError(
                "expected generate_transform_matrices(mesh, factors) with a mesh having .v and "
                ".f, or generate_transform_matrices(vertices, faces, factors); got "
                f"{type(mesh).__name__} and no factors"
            )
        vertices, faces, factors = mesh.v, mesh.f, faces_or_factors
    else:
        vertices, faces = mesh_or_vertices, faces_or_factors
    try:
        v = np.asarray(vertices)
    except Exception as e:  # noqa: BLE001 - anything numpy cannot convert
        raise InputError(f"vertices: not convertible to an array ({e})") from None
    if v.dtype.kind != "f":
        raise InputError(f"vertices: expected a float array, got dtype {v.dtype}")
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"vertices: expected an array of shape [V, 3], got shape {list(v.shape)}")
    if len(v) < 3:
        raise InputError(f"vertices: {len(v)} vertices, fewer than a triangle's 3")
    bad = np.flatnonzero(~np.isfinite(v).all(axis=1))
    if len(bad):
        raise InputError(f"vertices: row {bad[0]} is not finite ({v[bad[0]].tolist()})")
    try:
        f = np.asarray(faces)
    except Exception as e:  # noqa: BLE001
        raise InputError(f"faces: not convertible to an array ({e})") from None
    if f.dtype.kind not in "iu":
        raise InputError(f"faces: expected an integer array, got dtype {f.dtype}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise InputError(
            f"faces: expected an array of shape [F, 3], F > 0, got shape {list(f.shape)}"
        )
    if f.min() < 0 or f.max() >= len(v):
        row = int(np.flatnonzero(((f < 0) | (f >= len(v))).any(axis=1))[0])
        raise InputError(
            f"faces: row {row} ({f[row].tolist()}) refers to a vertex outside 0..{len(v) - 1}"
        )
    return v.astype(np.float64), f.astype(np.int64), factors


def _connectivity(n: int, faces: np.ndarray, dtype: type) -> scipy.sparse.csc_matrix:
    """psbody's ``get_vert_connectivity``: (a, b) counts the faces with edge ab, symmetric."""
    import scipy.sparse

    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    rows, cols = np.concatenate([a, b]), np.concatenate([b, a])
    ones = np.ones(len(rows), dtype)
    return scipy.sparse.csc_matrix((ones, (rows, cols)), shape=(n, n))


def _csc(parts: tuple, dtype: type) -> scipy.sparse.csc_matrix:
    import scipy.sparse

    data, indices, indptr, shape = parts
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=shape).tocsc().astype(dtype)


def _levels(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Any,
    form: str,
    pool: str,
    depool: str,
) -> Matrices:
    if form not in _FORMS:
        raise InputError(f"form: unknown form {form!r} (expected one of {', '.join(_FORMS)})")
    v, f, factors = _mesh_arrays(mesh_or_vertices, faces_or_factors, factors)
    counts = vertex_counts(len(v), factors)
    try:
        import scipy.sparse  # noqa: F401 - fail early, with the package's message
    except ImportError as e:
        raise ImportError(f"meshvae.sampling needs scipy (pip install scipy): {e}") from e
    dtype = np.float32 if form == "spiralnet" else np.float64
    steps = _meshvae._sampling_levels(v, f, counts[1:], pool=pool, depool=depool)
    V, F, D, U = [v], [f], [], []
    for survivors, _cluster, coarse_v, coarse_f, down, up in steps:
        # CoMA keeps each survivor where it was: V[i + 1] = D[i] @ V[i] (exactly, in float64).
        V.append(V[-1][survivors] if pool == "sampling" else coarse_v.astype(np.float64))
        F.append(coarse_f.astype(np.int64))
        D.append(_csc(down, dtype))
        U.append(_csc(up, dtype))
    A = [_connectivity(len(vi), fi, dtype) for vi, fi in zip(V, F)]
    M = [Mesh(vi, fi) for vi, fi in zip(V, F)]
    if form == "coma":
        return M, A, D, U
    if form == "neural3dmm":
        return M, A, D, U, F[1:]
    return M, A, D, U, F, V


@overload
def generate_transform_matrices(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Sequence[float] | None = None,
    *,
    form: Literal["spiralnet"] = "spiralnet",
) -> SpiralNetMatrices: ...
@overload
def generate_transform_matrices(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Sequence[float] | None = None,
    *,
    form: Literal["coma"],
) -> ComaMatrices: ...
@overload
def generate_transform_matrices(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Sequence[float] | None = None,
    *,
    form: Literal["neural3dmm"],
) -> Neural3dmmMatrices: ...
def generate_transform_matrices(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Sequence[float] | None = None,
    *,
    form: Form = "spiralnet",
) -> Matrices:
    """Levels 0..=L of a template mesh, decimated by ``factors``, and the matrices between them:
    the psbody-free ``mesh_sampling.generate_transform_matrices``.

    Call it as the references do, ``generate_transform_matrices(mesh, [4, 4, 4, 4])`` with any
    object having ``.v`` (float [V, 3]) and ``.f`` (int [F, 3]) -- a psbody ``Mesh``, a
    :class:`Mesh` -- or with arrays, ``generate_transform_matrices(vertices, faces, [4, 4, 4,
    4])``. The mesh must be a 2-manifold triangle mesh (with or without boundary). Level
    ``i + 1`` has ``ceil(n_i / factors[i])`` vertices, computed as the references do
    (:func:`vertex_counts`).

    Returns, by ``form``:

    - ``"spiralnet"`` (default, SpiralNet++'s ``utils/mesh_sampling.py``): ``(M, A, D, U, F,
      V)``, matrices float32;
    - ``"coma"`` (CoMA's ``lib/mesh_sampling.py``): ``(M, A, D, U)``, matrices float64 (CoMA's
      ``main.py`` casts them to float32 itself);
    - ``"neural3dmm"`` (Neural3DMM's ``mesh_sampling.py``): ``(M, A, D, U, F)`` with ``F`` the
      faces of levels 1..=L only (as theirs), matrices float64.

    where ``M[i]`` is a :class:`Mesh` ``(v, f)``; ``A[i]`` the ``n_i x n_i`` adjacency
    (psbody's ``get_vert_connectivity``: the number of faces on each edge, so 2 inside, 1 on a
    boundary); ``D[i]`` the ``n_{i+1} x n_i`` down-sampling (one 1 per row, on the survivor,
    ``V[i + 1] == D[i] @ V[i]``); ``U[i]`` the ``n_i x n_{i+1}`` up-sampling (three barycentric
    weights >= 0 summing to 1 per row, on the coarse triangle closest to the fine vertex);
    ``F[i]`` int64 [F_i, 3]; ``V[i]`` float64 [n_i, 3]. Matrices are
    ``scipy.sparse.csc_matrix``.

    Differences from the references (see the module documentation): the survivors are chosen by
    our manifold-preserving classical QEM rather than their unchecked half-edge collapse, so
    they differ from psbody's; the up-sampling weights always sum to 1 (theirs need not on
    edges); the ``M`` entries are named tuples, not psbody meshes; a factor < 1 or a level of
    fewer than 3 vertices is an error.

    Deterministic; the GIL is released during the computation. Raises
    :class:`~meshvae.InputError` for bad arrays, factors or forms, a non-manifold mesh, or a
    count the simplifier cannot reach while keeping the mesh's topology.
    """
    return _levels(mesh_or_vertices, faces_or_factors, factors, form, "sampling", "copy")


def edge_contraction_matrices(
    mesh_or_vertices: Any,
    faces_or_factors: Any,
    factors: Sequence[float] | None = None,
    *,
    form: Form = "spiralnet",
    pool: Literal["mean", "ours", "qem"] = "mean",
    depool: Literal["copy", "transpose"] = "copy",
) -> Matrices:
    """:func:`generate_transform_matrices` with meshvae's edge-contraction pooling instead of
    CoMA's sampling: the same calls, the same return forms and counts, so a CoMA / SpiralNet++
    / Neural3DMM network can use it unchanged.

    Each level is simplified by the paper's modified QEM (``pool="mean"`` or ``"ours"``,
    lambda = 0.001) or classical QEM (``pool="qem"``); ``D[i]`` is mean pooling over the
    simplifier's clusters (row ``c``: ``1 / |cluster c|`` on its members; every fine vertex in
    one cluster) and ``U[i]`` copies each coarse value back to its cluster (``depool="copy"``,
    so ``D[i] @ U[i]`` is the identity) or is ``D[i].T`` (``depool="transpose"``, as the
    authors' code). ``V[i + 1]`` holds the simplifier's coarse positions (quadric optima), so
    unlike CoMA's ``V[i + 1] != D[i] @ V[i]``. For equal factors ``f`` these are the operators of
    ``meshvae.Hierarchy.build(vertices, faces, levels=L, pool=pool, ratio=1 / f,
    depool=depool)`` (``.pooling(i)``, ``.depooling(i)``, ``.positions(i)``).
    """
    if pool not in ("mean", "ours", "qem"):
        raise InputError(f"pool: {pool!r} is not an edge-contraction pooler (mean, ours or qem)")
    return _levels(mesh_or_vertices, faces_or_factors, factors, form, pool, depool)


_KEYS = ("vertices", "face", "adj", "down_transform", "up_transform")


def _matrices(name: str, value: Any, shapes: list[tuple[int, int]]) -> list:
    import scipy.sparse

    items = _sequence(name, value, len(shapes))
    out = []
    for i, (m, shape) in enumerate(zip(items, shapes)):
        if not scipy.sparse.issparse(m):
            raise InputError(f"{name}[{i}]: expected a scipy.sparse matrix, got {type(m).__name__}")
        if tuple(m.shape) != shape:
            raise InputError(f"{name}[{i}]: expected shape {shape}, got {tuple(m.shape)}")
        m = m.tocsc()
        if m.dtype.kind not in "fiu" or not np.isfinite(m.data).all():
            raise InputError(f"{name}[{i}]: expected finite real values")
        out.append(m)
    return out


def _sequence(name: str, value: Any, length: int | None = None) -> list:
    if isinstance(value, (str, bytes, np.ndarray)) or not isinstance(value, Sequence):
        raise InputError(f"{name}: expected a list, got {type(value).__name__}")
    if length is not None and len(value) != length:
        raise InputError(f"{name}: expected {length} entries, got {len(value)}")
    return list(value)


def save_transform(
    path: str | os.PathLike[str],
    transform: Sequence[Any] | None = None,
    *,
    vertices: Sequence[npt.ArrayLike] | None = None,
    face: Sequence[npt.ArrayLike] | None = None,
    adj: Sequence[Any] | None = None,
    down_transform: Sequence[Any] | None = None,
    up_transform: Sequence[Any] | None = None,
) -> None:
    """Writes SpiralNet++'s ``transform.pkl``: a pickled dict with keys ``vertices`` (list of
    float [n_i, 3] arrays), ``face`` (list of int [F_i, 3] arrays), ``adj``, ``down_transform``
    and ``up_transform`` (lists of ``scipy.sparse.csc_matrix``), what its
    ``reconstruction/main.py`` writes and reads back with ``pickle.load(f, encoding='latin1')``.

    Give either ``transform``, the tuple :func:`generate_transform_matrices` returned (the
    six-value SpiralNet++ form; or a CoMA ``(M, A, D, U)`` / Neural3DMM ``(M, A, D, U, F)``
    tuple, whose vertices and faces are then read from ``M``), or all five keywords, as
    SpiralNet++'s dict: ``save_transform(path, vertices=V, face=F, adj=A, down_transform=D,
    up_transform=U)``.

    Checked before anything is written: ``vertices``, ``face`` and ``adj`` cover levels 0..=L,
    the two transforms the L steps, with matching shapes (``down_transform[i]``
    ``n_{i+1} x n_i``, ``up_transform[i]`` ``n_i x n_{i+1}``), finite values and faces in range;
    a problem raises :class:`~meshvae.InputError`. Matrices are stored as csc with their dtype,
    arrays as numpy arrays. The file is written to a temporary file beside ``path`` and renamed
    over it, so ``path`` is never half-written; a folder that does not exist or cannot be
    written raises :class:`~meshvae.FileError`.
    """
    keywords = (vertices, face, adj, down_transform, up_transform)
    if transform is not None:
        if any(k is not None for k in keywords):
            raise InputError("give either transform or the five keywords, not both")
        t = _sequence("transform", transform)
        if len(t) == 6:
            _, adj, down_transform, up_transform, face, vertices = t
        elif len(t) in (4, 5):
            meshes = _sequence("transform[0] (M)", t[0])
            adj, down_transform, up_transform = t[1], t[2], t[3]
            vertices = [getattr(m, "v", None) for m in meshes]
            face = [getattr(m, "f", None) for m in meshes]
        else:
            raise InputError(
                f"transform: expected (M, A, D, U, F, V), (M, A, D, U) or (M, A, D, U, F), "
                f"got {len(t)} values"
            )
    elif any(k is None for k in keywords):
        missing = [n for n, k in zip(_KEYS, keywords) if k is None]
        raise InputError(f"missing {', '.join(missing)} (give transform or all five keywords)")

    vs = _sequence("vertices", vertices)
    if not vs:
        raise InputError("vertices: expected at least one level")
    levels = len(vs)
    fs = _sequence("face", face, levels)
    counts = []
    out_v, out_f = [], []
    for i, (v, f) in enumerate(zip(vs, fs)):
        if v is None or f is None:
            raise InputError(f"level {i}: no vertices or faces")
        v = np.asarray(v)
        if v.dtype.kind != "f" or v.ndim != 2 or v.shape[1] != 3:
            raise InputError(
                f"vertices[{i}]: expected a float array of shape [V, 3], got {v.dtype} "
                f"{list(v.shape)}"
            )
        if not np.isfinite(v).all():
            raise InputError(f"vertices[{i}]: not finite")
        f = np.asarray(f)
        if f.dtype.kind not in "iu" or f.ndim != 2 or f.shape[1] != 3:
            raise InputError(
                f"face[{i}]: expected an integer array of shape [F, 3], got {f.dtype} "
                f"{list(f.shape)}"
            )
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise InputError(f"face[{i}]: a vertex index outside 0..{len(v) - 1}")
        counts.append(len(v))
        out_v.append(v)
        out_f.append(f)
    data = {
        "vertices": out_v,
        "face": out_f,
        "adj": _matrices("adj", adj, [(n, n) for n in counts]),
        "down_transform": _matrices(
            "down_transform", down_transform, list(zip(counts[1:], counts[:-1]))
        ),
        "up_transform": _matrices(
            "up_transform", up_transform, list(zip(counts[:-1], counts[1:]))
        ),
    }
    _write_atomically(os.fspath(path), pickle.dumps(data))


def _write_atomically(path: str, payload: bytes) -> None:
    folder = os.path.dirname(path) or "."
    temporary = os.path.join(
        folder, f".{os.path.basename(path)}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    )
    try:
        # O_EXCL: a fresh file of our own; 0o666 before the umask, as open(path, "wb") would.
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as e:
        raise FileError(f"{path}: cannot write ({e.strerror or e})") from e
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(payload)
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, path)
    except BaseException as e:
        try:
            os.unlink(temporary)
        except OSError:
            pass
        if isinstance(e, OSError):
            raise FileError(f"{path}: cannot write ({e.strerror or e})") from e
        raise
