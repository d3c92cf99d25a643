"""meshvae's network as PyTorch modules (needs torch: ``pip install torch``).

The layers and the whole network of the paper as ``meshvae train`` builds them, computing
what the Rust model computes (crates/meshvae: ``net/plan.rs``, ``candle/model``), on batches
``[B, V, C]`` on any torch device:

- :class:`ChebConv`: Chebyshev graph convolution on a level's rescaled Laplacian L̃;
- :class:`Pool`, :class:`DePool`: a hierarchy's pooling and de-pooling operators (sparse
  products; the ``max`` and ``graph`` poolers' maxima included);
- :class:`MeshBatchNorm`: batch norm over the batch and vertex axes, per channel;
- :class:`MeshVAE`: the network and its loss; :meth:`MeshVAE.from_folder` loads a model folder
  written by ``meshvae train``, :meth:`MeshVAE.save` writes one that every ``meshvae`` command
  reads.

Sparse operators are ``torch.sparse`` COO tensors held as non-persistent buffers: they move
with ``.to(device)`` but are not in ``state_dict()``, whose keys and shapes are exactly the
variables of a ``weights.safetensors`` (``enc.conv0.weight``, ``enc.bn0.running_mean``, …).

Modules: ``layers`` (the layers), ``model`` (:class:`MeshVAE` and its loss), ``folder`` (model
folders in and out, and the CPU engine's step to check torch's against).
"""

from __future__ import annotations

try:
    import torch  # noqa: F401
except ImportError as _error:  # pragma: no cover - exercised by a subprocess test
    raise ImportError(
        "meshvae.torch needs PyTorch, which is not installed: pip install torch "
        "(the rest of meshvae works without it)"
    ) from _error

# Beside the public names, the constants (BN_EPS, …).
from .folder import COPIED_FILES  # noqa: F401
from .layers import (  # noqa: F401
    BN_DECAY,
    BN_EPS,
    POOL_MODES,
    ChebConv,
    DePool,
    MeshBatchNorm,
    Pool,
    sparse_tensor,
)
from .model import (  # noqa: F401
    DEFAULT_CONFIG,
    FEATURE_CHANNELS,
    KL_VAR_EPS,
    LABEL_SCALE,
    Loss,
    LossWeights,
    MeshVAE,
    Output,
)

__all__ = [
    "ChebConv",
    "DEFAULT_CONFIG",
    "DePool",
    "LABEL_SCALE",
    "Loss",
    "LossWeights",
    "MeshBatchNorm",
    "MeshVAE",
    "Output",
    "Pool",
    "sparse_tensor",
]
