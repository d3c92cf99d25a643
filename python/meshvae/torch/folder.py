"""Model folders for :mod:`meshvae.torch`: :meth:`MeshVAE.from_folder` and :meth:`MeshVAE.save`
(a folder's weights, configuration, hierarchy and normalisation in; a folder every ``meshvae``
command reads out), and one step of the CPU engine on a folder model's variables, to check
torch's step against."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import Tensor

from .. import _meshvae
from .._meshvae import Model
from .model import DEFAULT_CONFIG, MeshVAE, _Labels, _PathLike

#: The files of a model folder that :meth:`MeshVAE.save` copies from the source folder (the
#: weights are written; the training run's log, status, checkpoint and plot are not copied:
#: they describe the source's training, not these weights).
COPIED_FILES = (
    "config.json",
    "hierarchy.safetensors",
    "hierarchy.json",
    "normalization.json",
    "split.json",
    "template.obj",
)


def load(
    cls: type[MeshVAE],
    path: _PathLike,
    device: torch.device | str | None,
    dtype: torch.dtype,
) -> MeshVAE:
    """:meth:`MeshVAE.from_folder`."""

    def refuse_other_networks(model_config: Mapping[str, Any]) -> None:
        net = model_config.get("net", "ours")
        if net != "ours":
            raise NotImplementedError(
                f"{path}: a {net} model (trained with --net {net}); meshvae.torch builds "
                "the paper's network only. Use meshvae.Model.load for its encoder and "
                "decoder."
            )

    config_file = Path(path) / "config.json"
    if config_file.is_file():  # refused before its weights are read
        try:
            refuse_other_networks(json.loads(config_file.read_text()).get("model", {}))
        except (ValueError, AttributeError):
            pass  # unreadable: Model.load says why
    source = Model.load(path)
    spec = source.config
    model_config = dict(spec["model"])
    refuse_other_networks(model_config)
    tensors, hierarchy, normalization = _meshvae._torch_model_state(source)
    model = cls(hierarchy, model_config, loss_weights=spec["train"]["loss"], dtype=dtype)
    state = {name: torch.from_numpy(np.asarray(a)) for name, a in tensors.items()}
    model.load_state_dict(state, strict=True)
    model._folder = Path(source.path)
    model._source_cache = source
    model.normalization = normalization
    model.template = source.template
    model.faces = source.faces
    model.eval()
    return model.to(device) if device is not None else model


def save(model: MeshVAE, path: _PathLike, like: _PathLike | None, overwrite: bool) -> Path:
    """:meth:`MeshVAE.save`."""
    path = Path(path)
    source = Model.load(like) if like is not None else model.source
    if source is None:
        raise ValueError(
            "save: the model did not come from a model folder; give like= a folder of "
            "the same configuration (trained by meshvae train) to copy the other files from"
        )
    ours = {k: v for k, v in model.config.items() if k != "net"}
    theirs = {**DEFAULT_CONFIG, **{k: v for k, v in source.config["model"].items() if k != "net"}}
    if theirs.get("pool") == "ours":
        theirs["pool"] = "mean"
    if ours != theirs:
        diff = {k: (theirs.get(k), ours.get(k)) for k in ours if ours.get(k) != theirs.get(k)}
        raise ValueError(
            f"save: the source folder {source.path} holds another configuration "
            f"(folder, this model): {diff}"
        )
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists (pass overwrite=True to replace it)")
    tensors = {
        name: t.detach().to("cpu", torch.float32).contiguous().numpy()
        for name, t in model.state_dict().items()
    }
    parent = path.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = parent / f".{path.name}.{os.getpid()}.tmp"
    old = parent / f".{path.name}.{os.getpid()}.old"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir()
        for name in COPIED_FILES:
            src = Path(source.path) / name
            if src.is_file():
                shutil.copy2(src, tmp / name)
        _meshvae._torch_write_weights(source, tmp / "weights.safetensors", tensors)
        if path.exists():
            path.rename(old)
        tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old.exists() and not path.exists():
            old.rename(path)
        raise
    shutil.rmtree(old, ignore_errors=True)
    return path


def engine_step(
    model: MeshVAE,
    x: Tensor,
    eps: Tensor,
    lr: float,
    betas: tuple[float, float] = (0.9, 0.999),
    adam_eps: float = 1e-8,
    labels: _Labels = None,
    double: bool = False,
) -> tuple[tuple[float, float, float, float], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """One step of ``meshvae train``'s CPU engine on a copy of ``model``'s variables (for
    checks): train-mode forward and backward on x with noise eps, then Adam from zero moments
    with ``lr`` (no rate scaling, no clipping). Returns ``(total, rec, kl, l2)``, every
    variable after the step, and the gradient of rec + kl of every trained variable (Adam adds
    the L2 term's, w_l2 · θ). ``double``: the engine runs in float64 (and returns float64
    arrays), which takes rounding out of a comparison with a float64 torch model. Needs a
    model from :meth:`MeshVAE.from_folder`."""
    source = model.source
    if source is None:
        raise ValueError("engine_step: needs a model from MeshVAE.from_folder")
    dtype = torch.float64 if double else torch.float32

    def host(t: Tensor) -> np.ndarray:
        return t.detach().to("cpu", dtype).numpy()

    tensors = {k: host(v) for k, v in model.state_dict().items()}
    c = model._conditions(labels, x.shape[0])
    w = model.loss_weights
    return _meshvae._torch_engine_step(
        source,
        tensors,
        host(x),
        host(eps),
        None if c is None else host(c),
        lr,
        betas,
        adam_eps,
        (w.rec, w.kl, w.l2),
        double,
    )
