"""meshvae: the meshvae crates from Python.

Mesh sets with their vertex order kept (:func:`load_set`, :func:`load_mesh`, :func:`save_obj`,
:func:`save_glb`), the paper's simplifier with its fine-to-coarse vertex map
(:func:`simplify`), the levels, Laplacians and pooling / de-pooling operators a mesh network
needs (:class:`Hierarchy`, as ``scipy.sparse.csr_matrix``), and ACAP deformation features with
their exact inverse (:func:`acap_features`, :class:`Normalization`, :func:`reconstruct`),
and models trained by ``meshvae train`` (:class:`Model`: ``encode``, ``decode``).
:mod:`meshvae.sampling` is a psbody-free drop-in for CoMA's, SpiralNet++'s and Neural3DMM's
``mesh_sampling.generate_transform_matrices``, with SpiralNet++'s ``transform.pkl``.
:mod:`meshvae.torch` (imported on its own, needs torch) is the network as PyTorch modules:
``ChebConv``, ``Pool``, ``DePool``, ``MeshVAE`` (``from_folder``, ``save``, ``loss``).

Arrays are numpy: positions float32 [V, 3] or [N, V, 3], faces int32 [F, 3], features float32
[N, V, 9]. Errors are :class:`MeshvaeError`: :class:`InputError` (also a ``ValueError``) or
:class:`FileError` (also an ``OSError``), carrying the message of the Rust crates.
"""

from ._errors import FileError, InputError, MeshvaeError
from ._meshvae import (
    FeatureFile,
    Hierarchy,
    MeshSet,
    Model,
    Normalization,
    Simplified,
    __version__,
    acap_features,
    load_features,
    load_mesh,
    load_set,
    reconstruct,
    save_glb,
    save_obj,
    simplify,
)
from . import sampling

__all__ = [
    "FeatureFile",
    "FileError",
    "Hierarchy",
    "InputError",
    "MeshSet",
    "MeshvaeError",
    "Model",
    "Normalization",
    "Simplified",
    "__version__",
    "acap_features",
    "load_features",
    "load_mesh",
    "load_set",
    "reconstruct",
    "sampling",
    "save_glb",
    "save_obj",
    "simplify",
]
