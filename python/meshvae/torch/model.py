"""The paper's whole network, :class:`MeshVAE`, and its loss, built from :mod:`.layers` as
``meshvae train`` builds it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence, Union, cast

import numpy as np
import torch
from torch import Tensor, nn

from .. import _meshvae
from .._meshvae import Hierarchy, Model, Normalization
from .layers import ChebConv, DePool, MeshBatchNorm, Pool, _host_dtype, _pool_mode, _TiedChebConv

#: ``ModelConfig::default()`` (crates/meshvae/src/net/config.rs): the paper's network as the
#: authors' code runs it. Keys as in a model folder's ``config.json`` (``"model"``).
DEFAULT_CONFIG: dict[str, Any] = {
    "structure": "CCPC",
    "conv": "spectral",
    "pool": "mean",
    "k": 3,
    "latent": 128,
    "channels": 9,
    "batch_norm": True,
    "last_encoder_linear": True,
    "tie_decoder_convs": False,
    "init_std": 0.02,
    "labels": [],
}

#: Channels of the per-vertex ACAP feature: the network's input and output width.
FEATURE_CHANNELS = 9
#: The value of a one-hot label's active entry (crates/meshvae/src/candle/model/cond.rs).
LABEL_SCALE = 8.0
#: ε in log(ε + σ²) of the KL term (net/latent.rs).
KL_VAR_EPS = 1e-8

_Labels = Union[Sequence[str], Tensor, None]
_PathLike = Union[str, "os.PathLike[str]"]


class LossWeights(NamedTuple):
    """Weights of the loss's terms (``LossWeights`` in crates/meshvae/src/net/loss_weights.rs;
    the authors' 40 / 3 / 1)."""

    rec: float = 40.0
    kl: float = 3.0
    l2: float = 1.0


class Loss(NamedTuple):
    """One evaluation of the loss: scalar tensors, each already weighted."""

    total: Tensor
    """rec + kl + l2: what to call ``backward()`` on."""
    rec: Tensor
    """w_rec · batch mean of Σ_{v,c} (x − x̂)²."""
    kl: Tensor
    """w_kl · batch mean of ½ Σ_j (μ² + σ² − log(10⁻⁸ + σ²) − 1)."""
    l2: Tensor
    """w_l2 · Σ over every trainable variable of ½‖w‖²."""


class Output(NamedTuple):
    """What :meth:`MeshVAE.forward` gives."""

    x_hat: Tensor
    """The decoded features [B, V, 9], in (−1, 1)."""
    mu: Tensor
    """The posterior's mean [B, latent]."""
    sigma: Tensor
    """The posterior's standard deviation [B, latent], in (0, √2)."""


class _ConvBlock:
    """conv → [batch norm] → [tanh], vertex-major. Not a module: the convolution and batch
    norm are registered under their variable names by :class:`MeshVAE`."""

    def __init__(self, conv: nn.Module, bn: MeshBatchNorm | None, tanh: bool) -> None:
        self.conv = conv
        self.bn = bn
        self.tanh = tanh

    def forward_vertex_major(self, h: Tensor) -> Tensor:
        y = self.conv.forward_vertex_major(h)  # type: ignore[operator]
        if self.bn is not None:
            y = self.bn(y)
        return torch.tanh(y) if self.tanh else y


class _Head(nn.Module):
    """A dense head: ``weight`` [width, latent], ``bias`` [latent] and, for a conditional
    model, ``label_weight`` [labels, latent]."""

    def __init__(
        self, width: int, latent: int, labels: int, init_std: float, dtype: torch.dtype
    ) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.randn(width, latent, dtype=dtype) * init_std)
        self.bias = nn.Parameter(torch.zeros(latent, dtype=dtype))
        if labels:
            self.label_weight = nn.Parameter(torch.zeros(labels, latent, dtype=dtype))


class _DecoderFc(nn.Module):
    """The decoder's dense layer z W_μᵀ + b (+ c W_dc): its weight is the μ head's."""

    def __init__(self, width: int, labels: int, dtype: torch.dtype) -> None:
        super().__init__()
        self.bias = nn.Parameter(torch.zeros(width, dtype=dtype))
        if labels:
            self.label_weight = nn.Parameter(torch.zeros(labels, width, dtype=dtype))


def _parse_structure(structure: str) -> list[str]:
    layers = []
    for i, ch in enumerate(structure):
        up = ch.upper()
        if up not in ("C", "P"):
            raise ValueError(
                f"structure: {structure!r}: character {ch!r} at position {i} is neither C "
                "(conv) nor P (pool)"
            )
        layers.append(up)
    if "C" not in layers:
        raise ValueError(f"structure: {structure!r} has no convolution (C)")
    return layers


class MeshVAE(nn.Module):
    """The paper's mesh VAE as ``meshvae train`` builds it (crates/meshvae/src/net/plan.rs,
    candle/model.rs), for ``config`` (a model folder's ``config.json["model"]``; missing keys
    take :data:`DEFAULT_CONFIG`, keyword arguments override) on ``hierarchy``.

    Encoder: the structure's convolutions (:class:`ChebConv`, order K) and poolings on the
    hierarchy's levels, each convolution followed by :class:`MeshBatchNorm` and tanh (the last
    one without batch norm, and linear when ``last_encoder_linear``); the coarsest level
    flattened vertex-major to ``[B, V_L·C]``; μ = hW_μ + b_μ, σ = √(2·sigmoid(hW_σ + b_σ)).
    Decoder: zW_μᵀ + b_dec (the dense layer is tied to the μ head), then the mirrored
    convolutions and de-poolings, all ending in tanh (batch norm on all but the output one).
    A conditional model (``labels`` in the config) adds a one-hot label (active entry
    :data:`LABEL_SCALE`) to both heads and the decoder's dense layer.

    Weights start as ``meshvae train``'s do in distribution (N(0, init_std²) weights, zero
    biases and label weights, γ = 1, β = 0), not in value. ``state_dict()`` holds exactly a
    ``weights.safetensors``' tensors, by the same names. Spatial convolutions
    (``conv = "spatial"``) and the other networks (``net``: tan2018, coma, spiralnet) are not
    built here (NotImplementedError).

    ``loss_weights``: the weights of :meth:`loss` (default 40 / 3 / 1, the folder's own for
    :meth:`from_folder`). ``dtype``: of every variable and operator (float32, as ``meshvae
    train``; float64 takes the hierarchy's operators as computed).
    """

    def __init__(
        self,
        hierarchy: Hierarchy,
        config: Mapping[str, Any] | None = None,
        *,
        loss_weights: LossWeights | Mapping[str, float] | None = None,
        dtype: torch.dtype = torch.float32,
        **overrides: Any,
    ) -> None:
        super().__init__()
        cfg = {**DEFAULT_CONFIG, **dict(config or {}), **overrides}
        unknown = sorted(set(cfg) - set(DEFAULT_CONFIG) - {"net"})
        if unknown:
            raise TypeError(
                f"MeshVAE: unknown configuration keys {unknown} (known: "
                f"{', '.join(sorted(DEFAULT_CONFIG))}, net)"
            )
        net = cfg.get("net", "ours")
        if net not in (None, "ours"):
            raise NotImplementedError(
                f"net {net!r}: meshvae.torch builds the paper's network only (ours); a "
                f"{net} model is run by meshvae.Model (encode, decode) and the meshvae command"
            )
        if cfg["conv"] != "spectral":
            raise NotImplementedError(
                f"conv {cfg['conv']!r}: meshvae.torch builds Chebyshev (spectral) convolutions "
                "only; the spatial ablation runs in meshvae train"
            )
        for key in ("k", "latent", "channels"):
            if int(cfg[key]) < 1:
                raise ValueError(f"{key}: must be at least 1, got {cfg[key]}")
        layers = _parse_structure(str(cfg["structure"]))
        pools = layers.count("P")
        pool = "mean" if cfg["pool"] == "ours" else str(cfg["pool"])
        if hierarchy.levels < pools:
            raise ValueError(
                f"hierarchy: has {hierarchy.levels} pooling steps; structure "
                f"{cfg['structure']} needs {pools}"
            )
        if pools and hierarchy.pool_kind != pool:
            raise ValueError(
                f"hierarchy: built with pooler {hierarchy.pool_kind}; the model's pool is {pool}"
            )
        labels = list(cfg.get("labels") or [])
        cfg.update(structure="".join(layers), pool=pool, labels=labels)
        if len(set(labels)) != len(labels) or any(not str(l).strip() for l in labels):
            raise ValueError(f"labels: empty or repeated labels in {labels}")
        self.config: dict[str, Any] = cfg
        self.labels: list[str] = labels
        self.latent = int(cfg["latent"])
        self.channels = int(cfg["channels"])
        self.K = int(cfg["k"])
        self.vertex_counts = list(hierarchy.vertex_counts[: pools + 1])
        self.loss_weights = _loss_weights(loss_weights)
        identity = _pool_mode(hierarchy.pool_kind) == "identity"
        # Without pooling every level is the template: level 0's operator serves all.
        host = _host_dtype(dtype)
        laplacians = [
            hierarchy.laplacian(0 if identity else l, dtype=host) for l in range(pools + 1)
        ]
        init_std = float(cfg["init_std"])
        flat = self.vertex_counts[-1] * self.channels

        enc, dec = nn.ModuleDict(), nn.ModuleDict()
        total = layers.count("C")
        # (index, level, c_in, c_out, batch norm, tanh) of each encoder convolution
        specs: list[tuple[int, int, int, int, bool, bool]] = []
        level = 0
        for layer in layers:
            if layer == "P":
                level += 1
                continue
            index = len(specs)
            last = index + 1 == total
            c_in = FEATURE_CHANNELS if index == 0 else self.channels
            bn = bool(cfg["batch_norm"]) and not last
            tanh = not (last and bool(cfg["last_encoder_linear"]))
            specs.append((index, level, c_in, self.channels, bn, tanh))

        self._encoder: list[Any] = []
        level, convs = 0, iter(specs)
        for layer in layers:
            if layer == "P":
                name = f"pool{level}"
                enc[name] = Pool.from_hierarchy(hierarchy, level, dtype)
                self._encoder.append(enc[name])
                level += 1
                continue
            index, lvl, c_in, c_out, bn, tanh = next(convs)
            enc_conv = ChebConv(
                laplacians[lvl], c_in, c_out, self.K, init_std=init_std, dtype=dtype
            )
            enc[f"conv{index}"] = enc_conv
            norm = MeshBatchNorm(c_out, dtype=dtype) if bn else None
            if norm is not None:
                enc[f"bn{index}"] = norm
            self._encoder.append(_ConvBlock(enc_conv, norm, tanh))
        enc["mu"] = _Head(flat, self.latent, len(labels), init_std, dtype)
        enc["sigma"] = _Head(flat, self.latent, len(labels), init_std, dtype)
        dec["fc"] = _DecoderFc(flat, len(labels), dtype)

        self._decoder: list[Any] = []
        tied = bool(cfg["tie_decoder_convs"])
        mirrored = iter(reversed(specs))
        for layer in reversed(layers):
            if layer == "P":
                level -= 1
                name = f"depool{level}"
                dec[name] = DePool.from_hierarchy(hierarchy, level, dtype)
                self._decoder.append(dec[name])
                continue
            index, lvl, c_in, c_out, _, _ = next(mirrored)
            bn = bool(cfg["batch_norm"]) and index != 0
            if tied:
                conv: nn.Module = _TiedChebConv(cast(ChebConv, enc[f"conv{index}"]))
                dec[f"tied{index}"] = conv  # its buffer only: the weight is the encoder's
            else:
                conv = ChebConv(
                    laplacians[lvl], c_out, c_in, self.K, init_std=init_std, dtype=dtype
                )
                dec[f"conv{index}"] = conv
            norm = MeshBatchNorm(c_in, dtype=dtype) if bn else None
            if norm is not None:
                dec[f"bn{index}"] = norm
            self._decoder.append(_ConvBlock(conv, norm, True))
        self.enc = enc
        self.dec = dec
        # DistributedDataParallel broadcasts buffers at every forward; the operators (sparse
        # matrices, pooling indices) are constant and equal everywhere, and DDP cannot
        # broadcast sparse tensors: it skips these names (its documented-by-use hook).
        persistent = set(self.state_dict())
        self._ddp_params_and_buffers_to_ignore = [
            name for name, _ in self.named_buffers() if name not in persistent
        ]
        self._folder: Path | None = None
        self._source_cache: Model | None = None
        self.normalization: Normalization | None = None
        self.template: np.ndarray | None = None
        self.faces: np.ndarray | None = None

    # ------------------------------------------------------------------ loading and saving

    @classmethod
    def from_folder(
        cls,
        path: _PathLike,
        device: torch.device | str | None = None,
        dtype: torch.dtype = torch.float32,
    ) -> "MeshVAE":
        """The model of a folder written by ``meshvae train`` (its best weights, batch norm's
        running statistics included; ``meshvae.Model.load`` reads it), in eval mode, on
        ``device`` (default CPU), its variables and operators of ``dtype``. Its normalisation
        and template come along (:meth:`features`, :meth:`positions`), and :meth:`save`
        copies the folder's other files. Models of the other networks (``--net
        tan2018|coma|spiralnet``) raise NotImplementedError."""
        from .folder import load  # folder.py imports this module

        return load(cls, path, device, dtype)

    @property
    def folder(self) -> Path | None:
        """The model folder this model was loaded from (None for one built from a hierarchy)."""
        return self._folder

    @property
    def source(self) -> Model | None:
        """The ``meshvae.Model`` of :attr:`folder` (None for a model built from a hierarchy)."""
        if self._source_cache is None and self._folder is not None:
            self._source_cache = Model.load(self._folder)
        return self._source_cache

    def __getstate__(self) -> dict[str, Any]:
        # Picklable (torch.save, copy.deepcopy): the Rust objects go as the folder and JSON.
        state = self.__dict__.copy()
        state["_source_cache"] = None
        if self.normalization is not None:
            state["normalization"] = ("json", self.normalization.to_json())
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        norm = state.get("normalization")
        if isinstance(norm, tuple):
            state["normalization"] = Normalization.from_json(norm[1])
        super().__setstate__(state)

    def save(
        self, path: _PathLike, *, like: _PathLike | None = None, overwrite: bool = False
    ) -> Path:
        """Writes a model folder that ``meshvae eval``, ``generate``, ``interpolate``,
        ``embed`` and ``reconstruct`` (and ``meshvae.Model.load``) read: this model's weights
        as ``weights.safetensors`` (every variable by its name, float32, with the metadata
        ``meshvae`` checks), and the folder's other files (config, hierarchy, normalisation,
        split, template) copied from the folder the model came from, or from ``like`` (a
        model folder of the same configuration, for a model built from a hierarchy).

        Written into a temporary folder beside ``path`` and renamed, so ``path`` is never
        half-written; an existing ``path`` is replaced only with ``overwrite=True``. Returns
        the folder."""
        from .folder import save  # folder.py imports this module

        return save(self, path, like, overwrite)

    # ------------------------------------------------------------------ data in and out

    def features(self, positions: Any) -> Tensor:
        """The network's input for meshes with the model's connectivity (positions [N, V, 3]
        or [V, 3], numpy or torch): ACAP features relative to the folder's template, normalised
        as its normalization.json says, exactly what ``meshvae`` feeds the encoder (computed in
        float32). [N, V, 9] (or [V, 9]) on the model's device, of its dtype. Needs a model
        from :meth:`from_folder`."""
        source = self.source
        if source is None:
            raise ValueError(
                "features: needs a model from MeshVAE.from_folder (the folder's template and "
                "normalisation); otherwise use meshvae.acap_features and Normalization.apply"
            )
        p = positions.detach().cpu().numpy() if isinstance(positions, Tensor) else positions
        p = np.asarray(p)
        single = p.ndim == 2
        x = _meshvae._torch_model_inputs(source, p[None] if single else p)
        out = torch.from_numpy(np.asarray(x)).to(self._device(), self._dtype())
        return out[0] if single else out

    def positions(self, x_hat: Any) -> np.ndarray:
        """Positions float32 [N, V, 3] (or [V, 3]) of decoded features [N, V, 9] (or [V, 9]):
        de-normalised, then the ACAP Poisson solve on the template (what ``meshvae.Model.decode``
        does after its decoder; positioned as it does). Needs :attr:`normalization`,
        :attr:`template` and :attr:`faces` (set by :meth:`from_folder`)."""
        if self.normalization is None or self.template is None or self.faces is None:
            raise ValueError(
                "positions: set normalization, template and faces (from_folder sets them)"
            )
        from .._meshvae import reconstruct

        f = x_hat.detach().cpu().float().numpy() if isinstance(x_hat, Tensor) else x_hat
        raw = self.normalization.invert(np.asarray(f, dtype=np.float32))
        return reconstruct(raw, self.template, self.faces)

    def one_hot(self, labels: Sequence[str]) -> Tensor:
        """One-hot rows [B, L] (active entry :data:`LABEL_SCALE`) of a conditional model's
        labels, on the model's device."""
        if not self.labels:
            raise ValueError("labels: the model is not conditional (trained without labels)")
        rows = torch.zeros(len(labels), len(self.labels))
        for i, label in enumerate(labels):
            if label not in self.labels:
                raise ValueError(
                    f"labels: {label!r} is not a label of this model; it knows "
                    f"{', '.join(self.labels)}"
                )
            rows[i, self.labels.index(label)] = LABEL_SCALE
        return rows.to(self._device(), self._dtype())

    def _conditions(self, labels: _Labels, batch: int) -> Tensor | None:
        if labels is None:
            if self.labels:
                raise ValueError(
                    "labels: the model is conditional; give one label per mesh, one of "
                    + ", ".join(self.labels)
                )
            return None
        if not self.labels:
            raise ValueError("labels: the model is not conditional (trained without labels)")
        c = labels if isinstance(labels, Tensor) else self.one_hot(list(labels))
        if tuple(c.shape) != (batch, len(self.labels)):
            raise ValueError(
                f"labels: shape {tuple(c.shape)}; expected [{batch}, {len(self.labels)}]"
            )
        return c

    @property
    def _mu_head(self) -> _Head:
        return cast(_Head, self.enc["mu"])

    @property
    def _sigma_head(self) -> _Head:
        return cast(_Head, self.enc["sigma"])

    @property
    def _fc(self) -> _DecoderFc:
        return cast(_DecoderFc, self.dec["fc"])

    def _device(self) -> torch.device:
        return self._fc.bias.device

    def _dtype(self) -> torch.dtype:
        return self._fc.bias.dtype

    # ------------------------------------------------------------------ the network

    def encode(self, x: Tensor, labels: _Labels = None) -> tuple[Tensor, Tensor]:
        """μ and σ [B, latent] of features x [B, V, 9] (labels: one per mesh, or one-hot rows
        [B, L], exactly for a conditional model). Batch norm uses the batch's statistics in
        training mode and the running ones in eval mode (``model.eval()``)."""
        if x.dim() != 3 or x.shape[1] != self.vertex_counts[0] or x.shape[2] != FEATURE_CHANNELS:
            raise ValueError(
                f"x: features of shape {tuple(x.shape)}; the model expects "
                f"[B, {self.vertex_counts[0]}, {FEATURE_CHANNELS}]"
            )
        batch = x.shape[0]
        c = self._conditions(labels, batch)
        h = x.transpose(0, 1)  # vertex-major inside, as the Rust network
        for step in self._encoder:
            h = step.forward_vertex_major(h)
        flat = h.transpose(0, 1).reshape(batch, -1)
        mu_head, sigma_head = self._mu_head, self._sigma_head
        mu = flat @ mu_head.weight + mu_head.bias
        s = flat @ sigma_head.weight + sigma_head.bias
        if c is not None:
            mu = mu + c @ mu_head.label_weight
            s = s + c @ sigma_head.label_weight
        return mu, torch.sqrt(torch.sigmoid(s) * 2.0)

    def decode(self, z: Tensor, labels: _Labels = None) -> Tensor:
        """Features x̂ [B, V, 9] in (−1, 1) from latent vectors z [B, latent]."""
        if z.dim() != 2 or z.shape[1] != self.latent:
            raise ValueError(f"z: shape {tuple(z.shape)}; expected [B, {self.latent}]")
        batch = z.shape[0]
        c = self._conditions(labels, batch)
        fc = self._fc
        h = z @ self._mu_head.weight.t() + fc.bias
        if c is not None:
            h = h + c @ fc.label_weight
        h = h.reshape(batch, self.vertex_counts[-1], self.channels).transpose(0, 1)
        for step in self._decoder:
            h = step.forward_vertex_major(h)
        return h.transpose(0, 1)

    def forward(self, x: Tensor, eps: Tensor | None = None, labels: _Labels = None) -> Output:
        """x̂, μ, σ of features x [B, V, 9], decoding z = μ + σ ⊙ ε. ε [B, latent] defaults to
        fresh N(0, I) noise in training mode and to 0 (z = μ, a reconstruction) in eval mode."""
        mu, sigma = self.encode(x, labels)
        if eps is None:
            eps = torch.randn_like(mu) if self.training else torch.zeros_like(mu)
        elif tuple(eps.shape) != tuple(mu.shape):
            raise ValueError(f"eps: shape {tuple(eps.shape)}; expected {tuple(mu.shape)}")
        return Output(self.decode(mu + sigma * eps, labels), mu, sigma)

    def l2_term(self) -> Tensor:
        """Σ over every trainable variable (weights, biases, batch norm's γ and β, label
        weights; W_μ once) of ½‖w‖², unweighted."""
        total = torch.zeros((), device=self._device(), dtype=self._dtype())
        for p in self.parameters():
            # torch's sum is a cascade (float32 error ~1e-7 of it), close enough to the
            # engine's float64 sum without a float64 copy of every weight at every step.
            total = total + p.square().sum() * 0.5
        return total

    def criterion(self, x: Tensor, output: Output) -> Loss:
        """The loss of ``output = model(x, ...)`` (for a model wrapped in
        DistributedDataParallel: ``criterion(x, ddp_model(x))``), weighted by
        :attr:`loss_weights` (crates/meshvae/src/train/loss.rs): w_rec · mean_b Σ (x − x̂)²
        + w_kl · mean_b ½ Σ_j (μ² + σ² − log(10⁻⁸ + σ²) − 1) + w_l2 · Σ ½‖w‖²."""
        w = self.loss_weights
        batch = x.shape[0]
        x_hat, mu, sigma = output
        rec = ((x - x_hat).square().sum(dtype=torch.float64) / batch).to(x.dtype) * w.rec
        var = sigma.square()
        kl_terms = mu.square() + var - torch.log(var + KL_VAR_EPS) - 1.0
        kl = kl_terms.sum() * 0.5 / batch * w.kl
        l2 = self.l2_term() * w.l2
        return Loss(rec + kl + l2, rec, kl, l2)

    def loss(self, x: Tensor, eps: Tensor | None = None, labels: _Labels = None) -> Loss:
        """The training loss of features x [B, V, 9] with noise ε [B, latent] (fresh N(0, I)
        noise when None, in training mode): ``criterion(x, self(x, eps, labels))``. In training
        mode batch norm uses (and updates its running statistics from) the batch, as a step of
        ``meshvae train`` does."""
        return self.criterion(x, self(x, eps, labels))

    def extra_repr(self) -> str:
        return (
            f"structure={self.config['structure']}, K={self.K}, latent={self.latent}, "
            f"vertex_counts={self.vertex_counts}"
            + (f", labels={self.labels}" if self.labels else "")
        )


def _loss_weights(value: LossWeights | Mapping[str, float] | None) -> LossWeights:
    if value is None:
        return LossWeights()
    if isinstance(value, LossWeights):
        return value
    return LossWeights(float(value["rec"]), float(value["kl"]), float(value["l2"]))
