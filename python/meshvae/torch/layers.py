"""The layers of :mod:`meshvae.torch`: Chebyshev convolution, batch norm over the batch and
vertex axes, and a hierarchy's pooling and de-pooling, on batches ``[B, V, C]``. Each layer also
has ``forward_vertex_major`` on ``[V, B, C]``, the layout :class:`~meshvae.torch.MeshVAE` keeps
inside (as the Rust network does)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from .._meshvae import Hierarchy

#: Batch norm's ε and the decay of its running statistics (net/batch_norm.rs).
BN_EPS = 1e-5
BN_DECAY = 0.9

#: How each pooler's operators apply (mesh-hierarchy's ``Pooler::mode``).
POOL_MODES = {
    "mean": "mean",
    "ours": "mean",
    "qem": "mean",
    "remesh": "mean",
    "sampling": "mean",  # the product keeps the survivors; de-pooling is barycentric
    "max": "signed_max",
    "graph": "max",
    "none": "identity",
}

_Sparse = Any  # a scipy.sparse matrix or a torch sparse tensor


def _host_dtype(dtype: torch.dtype) -> str:
    """The dtype to fetch a hierarchy's matrices in for a module of ``dtype``: float64 for a
    float64 module (the values as computed), float32 otherwise."""
    return "float64" if dtype == torch.float64 else "float32"


def sparse_tensor(matrix: _Sparse, dtype: torch.dtype = torch.float32) -> Tensor:
    """A ``scipy.sparse`` matrix (as :class:`meshvae.Hierarchy` gives them) as a coalesced
    ``torch.sparse_coo_tensor`` of ``dtype``; a torch sparse tensor is converted."""
    if isinstance(matrix, Tensor):
        if not matrix.is_sparse:
            matrix = matrix.to_sparse()
        return matrix.to(dtype).coalesce()
    coo = matrix.tocoo()
    indices = torch.from_numpy(np.vstack([coo.row, coo.col]).astype(np.int64))
    values = torch.from_numpy(np.asarray(coo.data)).to(dtype)
    return torch.sparse_coo_tensor(indices, values, coo.shape, check_invariants=True).coalesce()


def _product(op: Tensor, h: Tensor) -> Tensor:
    """op [n, m] (sparse) times h [m, ...] (vertex-major): [n, ...]."""
    rest = h.shape[1:]
    flat = h.reshape(h.shape[0], -1)
    return torch.sparse.mm(op, flat).reshape(op.shape[0], *rest)


def _vertex_major(module: Any, x: Tensor) -> Tensor:
    """Runs ``module.forward_vertex_major`` on x [B, V, C] (or [V, C])."""
    if x.dim() == 2:
        return module.forward_vertex_major(x.unsqueeze(1)).squeeze(1)
    if x.dim() != 3:
        raise ValueError(f"x: expected [B, V, C] or [V, C], got shape {tuple(x.shape)}")
    return module.forward_vertex_major(x.transpose(0, 1)).transpose(0, 1)


def _chebyshev(op: Tensor, weight: Tensor, k: int, h: Tensor) -> Tensor:
    """Σ_{k<K} T_k(op) h W_k for h [V, B, C_in] and weight [C_in·K, C_out] (row c·K + k):
    T_0 h = h, T_1 h = op h, T_k h = 2 op T_{k−1} h − T_{k−2} h."""
    v, b, c_in = h.shape
    if c_in * k != weight.shape[0]:
        raise ValueError(
            f"input of {c_in} channels; the convolution expects {weight.shape[0] // k}"
        )
    flat = h.reshape(v, b * c_in)
    terms = [flat]
    for order in range(1, k):
        lx = torch.sparse.mm(op, terms[-1])
        terms.append(lx if order == 1 else 2.0 * lx - terms[-2])
    # Whole channel blocks side by side (column k·C_in + c) copy far faster than stacking k
    # innermost, the weight's row order, so the weight is permuted instead; `linear` takes the
    # weight's gradient as gᵀx, which runs several times faster on CPU than xᵀg.
    c_out = weight.shape[1]
    stacked = torch.cat([t.reshape(v * b, c_in) for t in terms], dim=1)
    by_order = weight.reshape(c_in, k, c_out).transpose(0, 1).reshape(k * c_in, c_out)
    return nn.functional.linear(stacked, by_order.t()).reshape(v, b, c_out)


class ChebConv(nn.Module):
    """Chebyshev graph convolution y = Σ_{k<K} T_k(L̃) x W_k (+ b), as spectral-conv's
    ``ChebConv`` (crates/spectral-conv/src/cheb.rs): T_0 x = x, T_1 x = L̃x,
    T_k x = 2L̃ T_{k−1} x − T_{k−2} x.

    ``laplacian``: the rescaled Laplacian L̃ of a level (``Hierarchy.laplacian(level)``), V×V,
    scipy or torch sparse; held as a sparse buffer (not in ``state_dict``). ``weight`` is
    ``[in_channels·K, out_channels]`` with row ``c·K + k`` for input channel c and order k (the
    layout of a model folder's ``enc.conv{i}.weight``), drawn from N(0, init_std²). The bias is
    optional (zero-initialised); the paper's network has none (batch norm's β is its offset).
    Input [B, V, C_in] (or [V, C_in]), output [B, V, C_out].
    """

    laplacian: Tensor

    def __init__(
        self,
        laplacian: _Sparse,
        in_channels: int,
        out_channels: int,
        K: int = 3,
        bias: bool = False,
        init_std: float = 0.02,
        dtype: torch.dtype = torch.float32,
    ) -> None:
        super().__init__()
        if K < 1 or in_channels < 1 or out_channels < 1:
            raise ValueError("ChebConv: K, in_channels and out_channels must be at least 1")
        op = sparse_tensor(laplacian, dtype)
        if op.shape[0] != op.shape[1]:
            raise ValueError(f"laplacian: expected a square matrix, got shape {tuple(op.shape)}")
        self.register_buffer("laplacian", op, persistent=False)
        self.K = K
        self.in_channels = in_channels
        self.out_channels = out_channels
        weight = torch.randn(in_channels * K, out_channels, dtype=dtype) * init_std
        self.weight = nn.Parameter(weight)
        if bias:
            self.bias: nn.Parameter | None = nn.Parameter(torch.zeros(out_channels, dtype=dtype))
        else:
            self.register_parameter("bias", None)

    def forward_vertex_major(self, h: Tensor) -> Tensor:
        """h [V, B, C_in] → [V, B, C_out] (the layout :class:`MeshVAE` keeps)."""
        y = _chebyshev(self.laplacian, self.weight, self.K, h)
        return y if self.bias is None else y + self.bias

    def forward(self, x: Tensor) -> Tensor:
        return _vertex_major(self, x)

    def extra_repr(self) -> str:
        v = self.laplacian.shape[0]
        return f"V={v}, {self.in_channels} -> {self.out_channels}, K={self.K}, bias={self.bias is not None}"


class _TiedChebConv(nn.Module):
    """A decoder convolution tied to encoder convolution ``source`` (``tie_decoder_convs``):
    its adjoint on L̃ᵀ, Σ_k T_k(L̃ᵀ) Y W_kᵀ (per-order blocks of W transposed)."""

    op_t: Tensor

    def __init__(self, source: ChebConv) -> None:
        super().__init__()
        # Not a submodule: the weight belongs to the encoder (one variable, one state_dict key).
        object.__setattr__(self, "_source", source)
        self.register_buffer("op_t", source.laplacian.t().coalesce(), persistent=False)

    def forward_vertex_major(self, h: Tensor) -> Tensor:
        src: ChebConv = self._source  # type: ignore[assignment]
        k, c_in, c_out = src.K, src.in_channels, src.out_channels
        w = src.weight.reshape(c_in, k, c_out).permute(2, 1, 0).reshape(c_out * k, c_in)
        return _chebyshev(self.op_t, w, k, h)

    def forward(self, x: Tensor) -> Tensor:
        return _vertex_major(self, x)


class MeshBatchNorm(nn.Module):
    """Batch norm with one mean and variance per channel over the batch **and** vertex axes
    (crates/meshvae/src/candle/batch_norm.rs): y = γ (x − m) / √(v + ε) + β, ε = 1e-5.

    Training mode uses the batch's moments (biased variance, summed in float64) and moves the
    running statistics r ← 0.9·r + 0.1·batch; eval mode uses the running statistics. Variables:
    ``gamma``, ``beta`` (trained), ``running_mean``, ``running_var`` (buffers). Input [..., C].
    """

    running_mean: Tensor
    running_var: Tensor

    def __init__(
        self,
        channels: int,
        eps: float = BN_EPS,
        decay: float = BN_DECAY,
        dtype: torch.dtype = torch.float32,
    ) -> None:
        super().__init__()
        self.channels = channels
        self.eps = eps
        self.decay = decay
        self.gamma = nn.Parameter(torch.ones(channels, dtype=dtype))
        self.beta = nn.Parameter(torch.zeros(channels, dtype=dtype))
        self.register_buffer("running_mean", torch.zeros(channels, dtype=dtype))
        self.register_buffer("running_var", torch.ones(channels, dtype=dtype))

    def forward(self, x: Tensor) -> Tensor:
        if x.shape[-1] != self.channels or x.numel() == 0:
            raise ValueError(
                f"x: expected a non-empty [..., {self.channels}], got shape {tuple(x.shape)}"
            )
        flat = x.reshape(-1, self.channels)
        if self.training:
            wide = flat.double()
            mean64 = wide.mean(0)
            var64 = (wide - mean64).square().mean(0)
            mean, var = mean64.to(flat.dtype), var64.to(flat.dtype)
            with torch.no_grad():
                d = self.decay
                self.running_mean.copy_(self.running_mean * d + mean.detach() * (1.0 - d))
                self.running_var.copy_(self.running_var * d + var.detach() * (1.0 - d))
        else:
            mean, var = self.running_mean, self.running_var
        scale = torch.reciprocal(torch.sqrt(var + self.eps)) * self.gamma
        return ((flat - mean) * scale + self.beta).reshape(x.shape)

    def extra_repr(self) -> str:
        return f"{self.channels}, eps={self.eps}, decay={self.decay}"


def _pool_mode(kind: str) -> str:
    try:
        return POOL_MODES[kind]
    except KeyError:
        raise ValueError(
            f"pool: {kind!r} is not one of {', '.join(sorted(POOL_MODES))}"
        ) from None


class Pool(nn.Module):
    """Pooling from a level to the next coarser one with a hierarchy's pooling matrix P (m×n,
    ``Hierarchy.pooling(step)``), applied as the pooler says (``mode``; or use
    :meth:`from_hierarchy`, which reads it from the hierarchy):

    - ``"mean"`` (the poolers ``mean``, ``qem``, ``remesh``, ``sampling``): coarse = P · fine;
    - ``"signed_max"`` (``max``): per row of P, the member of largest magnitude with its sign
      (ties: the negative one);
    - ``"max"`` (``graph``): per row of P, the largest value;
    - ``"identity"`` (``none``): the input.

    For the maxima the gradient goes to the selected member (shared evenly among exact ties,
    where the Rust network picks one). Input [B, n, C] (or [n, C]), output [B, m, C].
    """

    matrix: Tensor
    rows: Tensor
    cols: Tensor

    def __init__(
        self, matrix: _Sparse, mode: str = "mean", dtype: torch.dtype = torch.float32
    ) -> None:
        super().__init__()
        if mode not in ("mean", "signed_max", "max", "identity"):
            raise ValueError(f"mode: {mode!r} is not mean, signed_max, max or identity")
        self.mode = mode
        op = sparse_tensor(matrix, dtype)
        self.register_buffer("matrix", op, persistent=False)
        indices = op.indices()
        self.register_buffer("rows", indices[0].clone(), persistent=False)
        self.register_buffer("cols", indices[1].clone(), persistent=False)

    @classmethod
    def from_hierarchy(
        cls, hierarchy: Hierarchy, step: int, dtype: torch.dtype = torch.float32
    ) -> "Pool":
        """The pooling of ``step`` (level ``step`` → ``step + 1``) as ``hierarchy``'s pooler
        applies it."""
        matrix = hierarchy.pooling(step, dtype=_host_dtype(dtype))
        return cls(matrix, _pool_mode(hierarchy.pool_kind), dtype)

    def forward_vertex_major(self, h: Tensor) -> Tensor:
        """h [n, B, C] → [m, B, C]."""
        if self.mode == "identity":
            return h
        if self.mode == "mean":
            return _product(self.matrix, h)
        m = self.matrix.shape[0]
        members = h.index_select(0, self.cols)
        index = self.rows.view(-1, *([1] * (h.dim() - 1))).expand_as(members)
        empty = h.new_zeros((m, *h.shape[1:]))
        hi = empty.scatter_reduce(0, index, members, "amax", include_self=False)
        if self.mode == "max":
            return hi
        lo = empty.scatter_reduce(0, index, members, "amin", include_self=False)
        return torch.where(-lo >= hi, lo, hi)

    def forward(self, x: Tensor) -> Tensor:
        return _vertex_major(self, x)

    def extra_repr(self) -> str:
        m, n = self.matrix.shape
        return f"{n} -> {m}, mode={self.mode}"


class DePool(nn.Module):
    """De-pooling back to the finer level with a hierarchy's de-pooling matrix D (n×m,
    ``Hierarchy.depooling(step)``): fine = D · coarse (for every pooler but ``none``, whose
    de-pooling is the identity). Input [B, m, C] (or [m, C]), output [B, n, C]."""

    matrix: Tensor

    def __init__(
        self, matrix: _Sparse, identity: bool = False, dtype: torch.dtype = torch.float32
    ) -> None:
        super().__init__()
        self.identity = identity
        self.register_buffer("matrix", sparse_tensor(matrix, dtype), persistent=False)

    @classmethod
    def from_hierarchy(
        cls, hierarchy: Hierarchy, step: int, dtype: torch.dtype = torch.float32
    ) -> "DePool":
        """The de-pooling of ``step`` (level ``step + 1`` → ``step``) of ``hierarchy``."""
        identity = _pool_mode(hierarchy.pool_kind) == "identity"
        return cls(hierarchy.depooling(step, dtype=_host_dtype(dtype)), identity, dtype)

    def forward_vertex_major(self, h: Tensor) -> Tensor:
        """h [m, B, C] → [n, B, C]."""
        return h if self.identity else _product(self.matrix, h)

    def forward(self, x: Tensor) -> Tensor:
        return _vertex_major(self, x)

    def extra_repr(self) -> str:
        n, m = self.matrix.shape
        return f"{m} -> {n}" + (", identity" if self.identity else "")
