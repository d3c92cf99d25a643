"""A straightforward PyTorch 2 CPU implementation of the paper's network, timed per training step.

meshvae's speed target is set against "what a researcher gets today from a straightforward
PyTorch 2 CPU implementation of the same network" (2 threads, f32, batch 32).
This is that implementation, written the way CoMA's and SpiralNet++'s PyTorch code is: sparse
Chebyshev recursion with `torch.sparse.mm`, `nn.BatchNorm1d`, `nn.Linear`, autograd and
`torch.optim.Adam`, activations kept vertex-major (`[V, B, C]`, so the sparse products need no
copies). It reads the operators from a meshvae model folder's `hierarchy.safetensors` (or the
`hierarchy.json` of older folders), so both run the same network on the same sparse matrices:

    CCPC, spectral convolution (K = 3), 9 channels, latent 128, batch norm after every
    convolution but the encoder's last (linear) and the decoder's last, tanh elsewhere,
    mean pooling and de-pooling by copy, a dense mean head, a deviation head sqrt(2 sigmoid),
    the decoder's dense layer tied to the mean head, loss 40 * SSE + 3 * KL + 1 * L2 / 2.

Usage (any model folder made by `meshvae train`, e.g. `--epochs 1`):

    python3 benches/reference/pytorch_step.py MODEL_DIR [--steps 30] [--threads 2] [--batch 32]

`--meshvae-torch` times `meshvae.torch.MeshVAE.from_folder(MODEL_DIR)` (the package's module of
the same network, where `meshvae` and torch are installed) in place of the network below.

Prints one JSON line: the median, 10th and 90th percentile step times in ms (the first three
steps dropped) and the peak resident memory. The input is random in (-0.95, 0.95), as in the
criterion bench `train`: a step's cost does not depend on the values.
"""

import argparse
import array
import json
import resource
import statistics
import sys
import time
from pathlib import Path

import torch
from torch import nn


# safetensors dtypes of the hierarchy file and their `array` type codes (little-endian host).
ARRAY_CODES = {"U16": "H", "U32": "I", "U64": "Q", "F32": "f", "F64": "d"}


def read_hierarchy(folder):
    """The hierarchy of a model folder in the layout of version 1's JSON (`levels[i]` with
    `vertex_count` and `laplacian`, `pooling[i]` with `pool` and `depool`, each matrix a dict
    of rows, cols, indptr, indices, values). Version 2 is a safetensors file: an 8-byte header
    length, a JSON header (`__metadata__["hierarchy"]` holds the sizes), then the arrays."""
    legacy = folder / "hierarchy.json"
    path = folder / "hierarchy.safetensors"
    if not path.is_file() and legacy.is_file():
        return json.loads(legacy.read_text())["hierarchy"]
    data = path.read_bytes()
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8 : 8 + n])
    outline = json.loads(header["__metadata__"]["hierarchy"])
    body = data[8 + n :]

    def tensor(name):
        info = header[name]
        start, end = info["data_offsets"]
        return array.array(ARRAY_CODES[info["dtype"]], body[start:end]).tolist()

    def matrix(prefix, size):
        parts = {k: tensor(f"{prefix}.{k}") for k in ("indptr", "indices", "values")}
        return {"rows": size["rows"], "cols": size["cols"], **parts}

    levels = [
        {
            "vertex_count": level["vertex_count"],
            "laplacian": matrix(f"level.{i}.laplacian", level["laplacian"]),
        }
        for i, level in enumerate(outline["levels"])
    ]
    pooling = [
        {
            "pool": matrix(f"pooling.{i}.pool", step["pool"]),
            "depool": matrix(f"pooling.{i}.depool", step["depool"]),
        }
        for i, step in enumerate(outline["pooling"])
    ]
    return {"levels": levels, "pooling": pooling}


def csr(m):
    """A hierarchy's CSR matrix as a torch sparse COO tensor (f32). COO, not CSR: the
    backward of `torch.sparse.mm` with a CSR matrix sorts its transpose on every call."""
    indptr = torch.tensor(m["indptr"], dtype=torch.int64)
    rows = torch.repeat_interleave(torch.arange(m["rows"]), indptr[1:] - indptr[:-1])
    cols = torch.tensor(m["indices"], dtype=torch.int64)
    vals = torch.tensor(m["values"], dtype=torch.float32)
    return torch.sparse_coo_tensor(
        torch.stack([rows, cols]), vals, (m["rows"], m["cols"])
    ).coalesce()


def spmm(a, x):
    """a [N, V] sparse times x [V, B, C] (vertex-major, so no copies) -> [N, B, C]."""
    v, b, c = x.shape
    return torch.sparse.mm(a, x.reshape(v, b * c)).reshape(a.shape[0], b, c)


class ChebConv(nn.Module):
    """sum_k T_k(L) X W_k, K = 3 (T0 = X, T1 = L X, T2 = 2 L T1 - T0); no bias; x [V, B, C]."""

    def __init__(self, lap, c_in, c_out, k=3):
        super().__init__()
        self.lap, self.k = lap, k
        # An nn.Linear (weight [c_out, k * c_in]) rather than x @ W with W [k * c_in, c_out]:
        # its weight gradient is g^T x, which MKL runs 5x faster on this machine than x^T g.
        self.lin = nn.Linear(k * c_in, c_out, bias=False)
        nn.init.normal_(self.lin.weight, std=0.02)

    def forward(self, x):
        terms = [x, spmm(self.lap, x)]
        for _ in range(2, self.k):
            terms.append(2 * spmm(self.lap, terms[-1]) - terms[-2])
        return self.lin(torch.cat(terms[: self.k], dim=2))


class Block(nn.Module):
    """conv -> optional batch norm (per channel, over batch and vertices) -> optional tanh."""

    def __init__(self, lap, c, bn, tanh):
        super().__init__()
        self.conv = ChebConv(lap, c, c)
        self.bn = nn.BatchNorm1d(c) if bn else None
        self.tanh = tanh

    def forward(self, x):
        y = self.conv(x)
        if self.bn is not None:
            y = self.bn(y.reshape(-1, y.shape[2])).reshape(y.shape)
        return torch.tanh(y) if self.tanh else y


class MeshVae(nn.Module):
    def __init__(self, hierarchy, channels=9, latent=128):
        super().__init__()
        l0, l1 = (csr(level["laplacian"]) for level in hierarchy["levels"][:2])
        self.pool = csr(hierarchy["pooling"][0]["pool"])
        self.depool = csr(hierarchy["pooling"][0]["depool"])
        self.v1 = hierarchy["levels"][1]["vertex_count"]
        c = channels
        self.enc = nn.ModuleList(
            [Block(l0, c, True, True), Block(l0, c, True, True), Block(l1, c, False, False)]
        )
        self.dec_coarse = Block(l1, c, True, True)
        self.dec_fine = nn.ModuleList([Block(l0, c, True, True), Block(l0, c, False, True)])
        self.mu = nn.Linear(self.v1 * c, latent)
        self.sigma = nn.Linear(self.v1 * c, latent)
        self.b_dec = nn.Parameter(torch.zeros(self.v1 * c))
        for lin in (self.mu, self.sigma):
            nn.init.normal_(lin.weight, std=0.02)
            nn.init.zeros_(lin.bias)

    def forward(self, x, eps):
        """x [V, B, C] (vertex-major) -> x_hat [V, B, C], mu, sigma [B, latent]."""
        h = self.enc[1](self.enc[0](x))
        h = self.enc[2](spmm(self.pool, h)).permute(1, 0, 2).flatten(1)
        mu = self.mu(h)
        sigma = torch.sqrt(2 * torch.sigmoid(self.sigma(h)))
        z = mu + sigma * eps
        d = (z @ self.mu.weight + self.b_dec).reshape(x.shape[1], self.v1, -1).permute(1, 0, 2)
        d = spmm(self.depool, self.dec_coarse(d))
        for block in self.dec_fine:
            d = block(d)
        return d, mu, sigma


def loss(model, x, eps):
    x_hat, mu, sigma = model(x, eps)
    rec = ((x - x_hat) ** 2).sum() / x.shape[1]
    s2 = sigma**2
    kl = (0.5 * (mu**2 + s2 - torch.log(1e-8 + s2) - 1).sum(dim=1)).mean()
    l2 = sum((p**2).sum() for n, p in model.named_parameters() if "bn" not in n) / 2
    return 40 * rec + 3 * kl + l2


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model", type=Path, help="a meshvae model folder (its hierarchy)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--meshvae-torch", action="store_true", help="time meshvae.torch.MeshVAE")
    args = ap.parse_args()
    try:
        hierarchy = read_hierarchy(args.model)
    except (OSError, KeyError, ValueError, json.JSONDecodeError) as e:
        sys.exit(f"{args.model}: no readable meshvae hierarchy ({e})")
    if args.steps < 4:
        sys.exit("--steps: at least 4 (the first three are dropped)")
    torch.set_num_threads(args.threads)
    torch.manual_seed(7)
    if args.meshvae_torch:
        from meshvae.torch import MeshVAE

        model = MeshVAE.from_folder(args.model).train()

        def step_loss(x, eps):
            return model.loss(x, eps).total  # [B, V, C] in; vertex-major inside

    else:
        model = MeshVae(hierarchy)

        def step_loss(x, eps):
            # The batch arrives mesh by mesh, [B, V, C]; the network runs vertex-major.
            return loss(model, x.permute(1, 0, 2).contiguous(), eps)

    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    v = hierarchy["levels"][0]["vertex_count"]
    x = torch.rand(args.batch, v, 9) * 1.9 - 0.95
    times = []
    for _ in range(args.steps):
        eps = torch.randn(args.batch, 128)
        t = time.perf_counter()
        opt.zero_grad(set_to_none=True)
        step_loss(x, eps).backward()
        opt.step()
        times.append((time.perf_counter() - t) * 1e3)
    kept = sorted(times[3:])
    q = statistics.quantiles(kept, n=10)
    print(
        json.dumps(
            {
                "vertices": v,
                "batch": args.batch,
                "threads": args.threads,
                "torch": torch.__version__,
                "network": "meshvae.torch" if args.meshvae_torch else "hand-written",
                "steps": len(kept),
                "median_ms": round(statistics.median(kept), 1),
                "p10_ms": round(q[0], 1),
                "p90_ms": round(q[-1], 1),
                "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
            }
        )
    )


if __name__ == "__main__":
    main()
