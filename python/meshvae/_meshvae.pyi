"""Type stubs of the compiled extension (python/src); see the docstrings there."""

from os import PathLike
from pathlib import Path
from typing import Any, Literal, Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse

__version__: str

_Path = str | PathLike[str]
_Floats = npt.ArrayLike  # any float array (float32 or float64), or nested lists
_Ints = npt.ArrayLike  # any integer array, or nested lists
_F32 = npt.NDArray[np.float32]
_I32 = npt.NDArray[np.int32]
_I64 = npt.NDArray[np.int64]

class MeshSet:
    """N meshes ("frames") of one connectivity."""

    def __init__(
        self,
        positions: _Floats,
        faces: _Ints,
        names: Sequence[str] | None = None,
        labels: Sequence[str] | None = None,
    ) -> None: ...
    @property
    def positions(self) -> _F32:
        """float32 [N, V, 3], read-only."""
    @property
    def faces(self) -> _I32:
        """int32 [F, 3], read-only."""
    @property
    def names(self) -> list[str]: ...
    @property
    def labels(self) -> list[str] | None: ...
    @property
    def vertex_count(self) -> int: ...
    def __len__(self) -> int: ...

def load_set(path: _Path) -> MeshSet:
    """Reads a folder of mesh files, a multi-frame GLB or a .mvset cache."""

def load_mesh(path: _Path) -> tuple[_F32, _I32]:
    """Reads one mesh file: (vertices float32 [V, 3], faces int32 [F, 3])."""

def save_obj(path: _Path, vertices: _Floats, faces: _Ints) -> None:
    """Writes one mesh as OBJ."""

def save_glb(
    path: _Path, frames: _Floats, faces: _Ints, names: Sequence[str] | None = None
) -> None:
    """Writes frames [N, V, 3] as one GLB with morph targets."""

class Simplified:
    """A simplified mesh and the map fine vertex -> coarse vertex."""

    @property
    def vertices(self) -> _F32:
        """float32 [M, 3]."""
    @property
    def faces(self) -> _I32:
        """int32 [F', 3]."""
    @property
    def cluster(self) -> _I64:
        """int64 [V]: the coarse vertex of every fine vertex."""
    @property
    def survivors(self) -> _I64 | None:
        """int64 [M]: the fine vertex kept as each coarse vertex (None for remesh)."""
    @property
    def report(self) -> dict[str, Any]:
        """The report `meshvae simplify --json` prints."""

def simplify(
    vertices: _Floats,
    faces: _Ints,
    ratio: float = 0.5,
    lam: float | None = None,
    method: Literal["modified-qem", "qem", "remesh"] = "modified-qem",
) -> Simplified:
    """Simplifies to `ratio` of the vertices; `lam` defaults to 0.001 for modified-qem."""

_Pooler = Literal["mean", "ours", "qem", "max", "sampling", "none", "graph", "remesh"]

class Hierarchy:
    """Levels 0..=L, their Laplacians, and the pooling operators between them."""

    @staticmethod
    def build(
        vertices: _Floats,
        faces: _Ints,
        levels: int = 1,
        pool: _Pooler = "mean",
        ratio: float = 0.5,
        depool: Literal["copy", "transpose"] = "copy",
    ) -> Hierarchy: ...
    @staticmethod
    def load(path: _Path) -> Hierarchy: ...
    def save(self, path: _Path) -> None: ...
    @property
    def levels(self) -> int:
        """Number of pooling steps L."""
    @property
    def pool_kind(self) -> str: ...
    @property
    def vertex_counts(self) -> list[int]: ...
    def laplacian(
        self, level: int, dtype: Literal["float32", "float64"] | None = None
    ) -> scipy.sparse.csr_matrix:
        """Rescaled Laplacian of `level`, V x V, float32 (default) or float64 (as computed)."""
    def pooling(
        self, step: int, dtype: Literal["float32", "float64"] | None = None
    ) -> scipy.sparse.csr_matrix:
        """Pooling matrix P of `step`, m x n (dtype as laplacian): coarse = P @ fine."""
    def depooling(
        self, step: int, dtype: Literal["float32", "float64"] | None = None
    ) -> scipy.sparse.csr_matrix:
        """De-pooling matrix D of `step`, n x m (dtype as laplacian): fine = D @ coarse."""
    def cluster(self, step: int) -> _I64 | None: ...
    def positions(self, level: int) -> _F32: ...
    def faces(self, level: int) -> _I32: ...
    def pool(self, step: int, x: _Floats) -> _F32:
        """[n, C] or [B, n, C] -> [m, C] or [B, m, C], as the network pools."""
    def depool(self, step: int, x: _Floats) -> _F32:
        """[m, C] or [B, m, C] -> [n, C] or [B, n, C]."""

def _sampling_levels(
    vertices: _Floats,
    faces: _Ints,
    counts: Sequence[int],
    pool: Literal["sampling", "mean", "ours", "qem"] = "sampling",
    depool: Literal["copy", "transpose"] = "copy",
) -> list[
    tuple[
        _I64,
        _I64,
        _F32,
        _I32,
        tuple[npt.NDArray[np.float64], _I64, _I64, tuple[int, int]],
        tuple[npt.NDArray[np.float64], _I64, _I64, tuple[int, int]],
    ]
]:
    """Private (use meshvae.sampling): per step (survivors, cluster, coarse vertices, coarse
    faces, down, up), each matrix as CSR (data, indices, indptr, shape)."""

def acap_features(
    mesh_set: MeshSet,
    rest: int | str = 0,
    *,
    integrable: bool = True,
    principal: bool = False,
    normal_weight: float = 1.0,
) -> _F32:
    """Raw ACAP features, float32 [N, V, 9]."""

def reconstruct(
    features: _Floats, template_vertices: _Floats, template_faces: _Ints
) -> _F32:
    """Positions float32 [N, V, 3] (or [V, 3]) from raw features [N, V, 9] (or [V, 9])."""

class Normalization:
    """The map of features into [-0.95, 0.95] and back."""

    def __init__(
        self,
        rotation_min: float,
        rotation_max: float,
        scale_min: float,
        scale_max: float,
        clamp: float | None = None,
    ) -> None: ...
    @staticmethod
    def fit(features: _Floats, quantile: float = 0.0) -> Normalization: ...
    def apply(self, features: _Floats) -> _F32: ...
    def invert(self, normalized: _Floats) -> _F32: ...
    def to_json(self) -> str: ...
    @staticmethod
    def from_json(text: str) -> Normalization: ...
    @property
    def rotation_min(self) -> float: ...
    @property
    def rotation_max(self) -> float: ...
    @property
    def scale_min(self) -> float: ...
    @property
    def scale_max(self) -> float: ...
    @property
    def clamp(self) -> float | None: ...

class FeatureFile:
    """What `meshvae features` wrote."""

    @property
    def features(self) -> _F32: ...
    @property
    def normalized(self) -> bool: ...
    @property
    def normalization(self) -> Normalization | None: ...
    @property
    def names(self) -> list[str]: ...

def load_features(path: _Path) -> FeatureFile: ...

class Model:
    """A model trained by `meshvae train`, in inference mode: ours, or another network
    (`--net tan2018|coma|spiralnet`; `config["model"]["net"]`), whose posterior is the point mu
    (sigma 0) for the plain auto-encoders CoMA and SpiralNet++."""

    @staticmethod
    def load(path: _Path) -> Model: ...
    def encode(
        self, positions: _Floats, labels: Sequence[str] | None = None
    ) -> tuple[_F32, _F32]:
        """[N, V, 3] (or [V, 3]) -> (mu, sigma), float32 [N, latent] (or [latent]) each."""
    def decode(self, z: _Floats, labels: Sequence[str] | None = None) -> _F32:
        """[N, latent] (or [latent]) -> positions float32 [N, V, 3] (or [V, 3])."""
    @property
    def config(self) -> dict[str, Any]:
        """The model folder's config.json."""
    @property
    def latent(self) -> int: ...
    @property
    def vertex_count(self) -> int: ...
    @property
    def faces(self) -> _I32: ...
    @property
    def template(self) -> _F32: ...
    @property
    def labels(self) -> list[str]:
        """A conditional model's class labels; empty for an unconditional one."""
    @property
    def path(self) -> Path: ...

# Private: what meshvae.torch reads from and writes to model folders (python/src/torch_support.rs).

def _torch_model_state(
    model: Model,
) -> tuple[dict[str, _F32], Hierarchy, Normalization | None]:
    """The model's variables by name (float32), its hierarchy, its normalisation (None for a
    position network)."""

def _torch_model_inputs(model: Model, positions: _Floats) -> _F32:
    """The network's input [N, V, 9] of positions [N, V, 3]: normalised ACAP features."""

def _torch_write_weights(
    model: Model, path: _Path, tensors: dict[str, _F32], epoch: int | None = None
) -> None:
    """Writes every variable of the model as a weights file meshvae reads."""

def _torch_engine_step(
    model: Model,
    tensors: dict[str, _F32],
    x: _Floats,
    eps: _Floats,
    labels: _Floats | None,
    lr: float,
    betas: tuple[float, float],
    adam_eps: float,
    loss_weights: tuple[float, float, float],
) -> tuple[tuple[float, float, float, float], dict[str, _F32], dict[str, _F32]]:
    """One CPU-engine step: (total, rec, kl, l2), variables after, gradients of rec + kl."""
