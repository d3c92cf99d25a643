"""meshvae.torch: the layers against the Rust ones (Hierarchy.pool / depool, a dense
Chebyshev reference), the whole network against meshvae.Model (encoder μ, decoded positions),
training in torch, saving a folder the command line reads, and one torch step against one
step of the CPU engine. Skipped where torch is not importable; the CUDA variants where no GPU
is."""

import copy
import json
import os
import subprocess

import numpy as np
import pytest

torch = pytest.importorskip(
    "torch", reason="SKIPPED: torch is not importable, so meshvae.torch is not tested (pip install torch)"
)

import meshvae  # noqa: E402
from meshvae.torch import (  # noqa: E402
    ChebConv,
    DePool,
    MeshBatchNorm,
    MeshVAE,
    Pool,
)
from meshvae.torch.folder import engine_step as _engine_step  # noqa: E402
from meshvae.torch.layers import _TiedChebConv  # noqa: E402
from conftest import run_cli  # noqa: E402

@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """torch on one thread: on a 2-core machine shared with other work (a developer's, with
    training runs beside), two OpenMP threads made every operation wait for a core, a horse
    step 8x slower (4 s instead of 0.5 s); alone on the machine one thread costs at most 2x."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


DEVICES = [
    "cpu",
    pytest.param(
        "cuda",
        marks=pytest.mark.skipif(
            not torch.cuda.is_available(), reason="SKIPPED: no CUDA device (torch.cuda.is_available() is False)"
        ),
    ),
]


def relative(got, want):
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    return np.abs(got - want).max() / np.abs(want).max()


def diagonal(positions):
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    return np.linalg.norm(p.max(0) - p.min(0))


def centred(p):
    p = np.asarray(p, np.float64)
    return p - p.mean(axis=-2, keepdims=True)


def rms(truth, reconstructed):
    """meshvae eval's RMS: per coordinate, after aligning centroids."""
    d = centred(truth) - centred(reconstructed)
    return float(np.sqrt((d**2).sum() / d.size))


# ---------------------------------------------------------------------------- layers


@pytest.mark.parametrize("pool", ["mean", "qem", "max", "graph", "sampling", "none"])
def test_pool_and_depool_equal_the_rust_pooling(sphere, pool):
    vertices, faces = sphere
    h = meshvae.Hierarchy.build(vertices, faces, levels=1, pool=pool)
    n, m = h.vertex_counts
    x = np.random.default_rng(1).normal(size=(3, n, 5)).astype(np.float32)
    down = Pool.from_hierarchy(h, 0)
    coarse = down(torch.from_numpy(x))
    assert coarse.shape == (3, m, 5)
    np.testing.assert_allclose(coarse.numpy(), h.pool(0, x), atol=1e-6)
    np.testing.assert_allclose(down(torch.from_numpy(x[1])).numpy(), h.pool(0, x[1]), atol=1e-6)
    y = np.random.default_rng(2).normal(size=(3, m, 5)).astype(np.float32)
    up = DePool.from_hierarchy(h, 0)
    np.testing.assert_allclose(up(torch.from_numpy(y)).numpy(), h.depool(0, y), atol=1e-6)
    # Gradients reach the input (for the maxima: the selected members).
    xt = torch.from_numpy(x).requires_grad_()
    down(xt).sum().backward()
    assert xt.grad is not None and xt.grad.abs().sum() > 0


def test_chebconv_equals_the_recurrence_and_its_gradient_checks(sphere):
    vertices, faces = sphere
    h = meshvae.Hierarchy.build(vertices, faces, levels=1)
    lap = h.laplacian(0)
    conv = ChebConv(lap, 4, 6, K=3)
    assert conv.weight.shape == (12, 6) and conv.bias is None
    assert "laplacian" not in conv.state_dict() and conv.laplacian.is_sparse
    x = np.random.default_rng(3).normal(size=(2, lap.shape[0], 4))
    dense = lap.toarray().astype(np.float64)
    t0 = x
    t1 = np.einsum("uv,bvc->buc", dense, t0)
    t2 = 2 * np.einsum("uv,bvc->buc", dense, t1) - t0
    w = conv.weight.detach().numpy().astype(np.float64).reshape(4, 3, 6)  # row c*K + k
    want = sum(np.einsum("bvc,co->bvo", t, w[:, k, :]) for k, t in enumerate((t0, t1, t2)))
    got = conv(torch.from_numpy(x).float()).detach().numpy()
    assert relative(got, want) < 1e-5
    # Bias, one mesh [V, C], and float64 gradients against finite differences.
    conv_b = ChebConv(lap, 2, 3, K=2, bias=True).double()
    with torch.no_grad():
        conv_b.bias.copy_(torch.tensor([0.5, -1.0, 2.0]))
    x64 = torch.randn(lap.shape[0], 2, dtype=torch.float64, requires_grad=True)
    assert conv_b(x64).shape == (lap.shape[0], 3)
    assert torch.autograd.gradcheck(lambda t: conv_b(t), (x64,))


def test_tied_convolution_is_the_adjoint(sphere):
    vertices, faces = sphere
    lap = meshvae.Hierarchy.build(vertices, faces, levels=1).laplacian(0)
    conv = ChebConv(lap, 4, 6, K=3).double()
    tied = _TiedChebConv(conv)
    x = torch.randn(2, lap.shape[0], 4, dtype=torch.float64)
    y = torch.randn(2, lap.shape[0], 6, dtype=torch.float64)
    with torch.no_grad():
        lhs = (conv(x) * y).sum()
        rhs = (x * tied(y)).sum()
    assert abs(float(lhs - rhs)) < 1e-9 * abs(float(lhs))


def test_batch_norm_uses_batch_and_vertex_axes():
    bn = MeshBatchNorm(3)
    x = torch.randn(4, 50, 3) * torch.tensor([1.0, 2.0, 3.0]) + torch.tensor([0.0, 1.0, -2.0])
    y = bn(x)
    flat = y.reshape(-1, 3)
    assert flat.mean(0).abs().max() < 1e-5
    batch_mean = x.reshape(-1, 3).double().mean(0).float()
    torch.testing.assert_close(bn.running_mean, 0.1 * batch_mean)
    batch_var = x.reshape(-1, 3).double().var(0, unbiased=False).float()
    torch.testing.assert_close(bn.running_var, 0.9 + 0.1 * batch_var)
    bn.eval()
    want = (x - bn.running_mean) / torch.sqrt(bn.running_var + 1e-5)
    torch.testing.assert_close(bn(x), want)
    assert set(bn.state_dict()) == {"gamma", "beta", "running_mean", "running_var"}


def test_model_from_a_hierarchy_and_its_state_dict_names(sphere):
    vertices, faces = sphere
    h = meshvae.Hierarchy.build(vertices, faces, levels=1)
    model = MeshVAE(h, latent=8)
    names = {
        "enc.conv0.weight", "enc.conv1.weight", "enc.conv2.weight",
        "enc.bn0.gamma", "enc.bn0.beta", "enc.bn0.running_mean", "enc.bn0.running_var",
        "enc.bn1.gamma", "enc.bn1.beta", "enc.bn1.running_mean", "enc.bn1.running_var",
        "enc.mu.weight", "enc.mu.bias", "enc.sigma.weight", "enc.sigma.bias", "dec.fc.bias",
        "dec.conv2.weight", "dec.conv1.weight", "dec.conv0.weight",
        "dec.bn2.gamma", "dec.bn2.beta", "dec.bn2.running_mean", "dec.bn2.running_var",
        "dec.bn1.gamma", "dec.bn1.beta", "dec.bn1.running_mean", "dec.bn1.running_var",
    }
    assert set(model.state_dict()) == names
    assert model.enc["mu"].weight.shape == (h.vertex_counts[1] * 9, 8)
    x = torch.rand(3, h.vertex_counts[0], 9) * 1.8 - 0.9
    out = model(x)
    assert out.x_hat.shape == x.shape and out.mu.shape == out.sigma.shape == (3, 8)
    assert (out.sigma > 0).all() and (out.sigma < 2**0.5).all() and out.x_hat.abs().max() < 1
    loss = model.loss(x, torch.zeros(3, 8))
    assert torch.isclose(loss.total, loss.rec + loss.kl + loss.l2)
    l2 = sum(0.5 * float((p.detach().double() ** 2).sum()) for p in model.parameters())
    assert abs(float(loss.l2.detach()) - l2) < 1e-5 * l2
    # A copy (and a pickle) keeps working: the Rust objects are not in the state.
    twin = copy.deepcopy(model).eval()
    model.eval()
    torch.testing.assert_close(twin(x).x_hat, model(x).x_hat)
    with pytest.raises(ValueError, match="hierarchy: built with pooler mean; the model's pool is max"):
        MeshVAE(h, pool="max")
    with pytest.raises(NotImplementedError, match="spatial"):
        MeshVAE(h, conv="spatial")
    with pytest.raises(NotImplementedError, match="coma"):
        MeshVAE(h, net="coma")
    with pytest.raises(TypeError, match="unknown configuration keys"):
        MeshVAE(h, latnet=8)
    with pytest.raises(ValueError, match="the model did not come from a model folder"):
        model.save("never-written")
    assert not os.path.exists("never-written")


def test_distributed_data_parallel_wraps_the_model(sphere, tmp_path):
    """One process of a gloo group (CPU): DDP accepts the model (its sparse buffers are left
    out of the broadcast) and a step through the wrapper trains."""
    import torch.distributed as dist

    vertices, faces = sphere
    model = MeshVAE(meshvae.Hierarchy.build(vertices, faces, levels=1), latent=8)
    dist.init_process_group("gloo", init_method=f"file://{tmp_path / 'rendezvous'}", rank=0, world_size=1)
    try:
        ddp = torch.nn.parallel.DistributedDataParallel(model)
        opt = torch.optim.Adam(ddp.parameters(), lr=1e-3)
        x = torch.rand(2, vertices.shape[0], 9) * 1.8 - 0.9
        before = model.enc["conv0"].weight.detach().clone()
        loss = model.criterion(x, ddp(x))
        opt.zero_grad()
        loss.total.backward()
        opt.step()
        assert not torch.equal(before, model.enc["conv0"].weight)
    finally:
        dist.destroy_process_group()


# ---------------------------------------------------------------------------- trained models


@pytest.fixture(scope="module")
def horse_torch(horse_model):
    return MeshVAE.from_folder(horse_model)


@pytest.mark.parametrize("device", DEVICES)
def test_encoder_and_decoder_equal_the_rust_model(horse_model, horse, device):
    model = MeshVAE.from_folder(horse_model, device=device)
    assert not model.training
    rust = meshvae.Model.load(horse_model)
    split = json.loads((horse_model / "split.json").read_text())
    positions = horse.positions[split["test"]]
    x = model.features(positions)
    assert x.device.type == device and x.shape == (len(positions), horse.vertex_count, 9)
    mu_rust, sigma_rust = rust.encode(positions)
    with torch.no_grad():
        mu, sigma = model.encode(x)
        x_hat = model.decode(torch.from_numpy(mu_rust).to(device))
    mu_error = relative(mu.cpu(), mu_rust)
    assert mu_error < 1e-5, f"mu differs by {mu_error:.2e} of its largest value"
    assert relative(sigma.cpu(), sigma_rust) < 1e-5
    want = rust.decode(mu_rust)  # positions, as Model.decode gives them
    got = model.positions(x_hat)
    error = np.abs(centred(got) - centred(want)).max() / diagonal(want)
    assert error < 1e-5, f"decoded positions differ by {error:.2e} of the bounding-box diagonal"
    print(f"\n[{device}] encoder mu: {mu_error:.2e} (relative); decoded: {error:.2e} of the diagonal")


@pytest.mark.parametrize("device", DEVICES)
def test_adam_steps_lower_the_loss(horse_torch, horse_model, horse, device):
    model = copy.deepcopy(horse_torch).to(device)
    split = json.loads((horse_model / "split.json").read_text())
    x = model.features(horse.positions[split["train"]])
    generator = torch.Generator().manual_seed(0)
    eps = torch.randn(len(x), model.latent, generator=generator).to(device)

    def measured():
        with torch.no_grad():
            model.train()
            return float(model.loss(x, eps).total)

    before = measured()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3, betas=(0.9, 0.95))
    model.train()
    for step in range(50):
        batch = x[torch.randperm(len(x), generator=generator)[:8].to(device)]
        loss = model.loss(batch)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
    after = measured()
    print(f"\n[{device}] loss on the training meshes: {before:.1f} before, {after:.1f} after 50 steps")
    assert after < 0.8 * before, (before, after)


@pytest.mark.parametrize("device", DEVICES)
def test_save_writes_a_folder_the_cli_evaluates(cli, horse_torch, horse_model, horse, tmp_path, device):
    model = copy.deepcopy(horse_torch).to(device)
    split = json.loads((horse_model / "split.json").read_text())
    x = model.features(horse.positions[split["train"]])
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    model.train()
    for _ in range(3):  # weights (and running statistics) unlike the source folder's
        loss = model.loss(x[:8])
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
    model.eval()
    out = model.save(tmp_path / "tuned")
    assert sorted(os.listdir(tmp_path)) == ["tuned"]  # no temporary folder left
    assert {"config.json", "hierarchy.safetensors", "normalization.json", "split.json",
            "template.obj", "weights.safetensors"} == set(os.listdir(out))
    with pytest.raises(FileExistsError):
        model.save(out)

    # The same names, shapes and dtype as the folder meshvae train wrote.
    from safetensors import safe_open

    with safe_open(horse_model / "weights.safetensors", "np") as a, safe_open(out / "weights.safetensors", "np") as b:
        assert set(a.keys()) == set(b.keys()) == set(model.state_dict())
        for key in a.keys():
            ta, tb = a.get_tensor(key), b.get_tensor(key)
            assert ta.shape == tb.shape and ta.dtype == tb.dtype == np.float32, key
            np.testing.assert_array_equal(tb, model.state_dict()[key].cpu().numpy())
        assert b.metadata()["format"] == "meshvae-weights"

    report = json.loads(run_cli(cli, "eval", out, "--json"))
    assert report["stop_reason"] == "unrecorded" and report["epochs"] is None  # torch's training
    test_ids = split["test"]
    with torch.no_grad():
        x_hat = model(model.features(horse.positions[test_ids])).x_hat
    ours = rms(horse.positions[test_ids], model.positions(x_hat))
    print(f"\n[{device}] test RMS: meshvae eval {report['test_rms']:.9g}, torch {ours:.9g}")
    assert abs(ours - report["test_rms"]) < 1e-5 * report["test_rms"], (ours, report["test_rms"])

    # Overwriting replaces the folder whole; the Rust model reads the new weights.
    model.save(out, overwrite=True)
    assert sorted(os.listdir(tmp_path)) == ["tuned"]
    mu_rust, _ = meshvae.Model.load(out).encode(horse.positions[:2])
    with torch.no_grad():
        mu, _ = model.encode(model.features(horse.positions[:2]))
    assert relative(mu.cpu(), mu_rust) < 1e-5


STEP_LR, ADAM_EPS = 1e-3, 1e-8  # the compared step's learning rate and Adam's ε


def _first_adam_step(g):
    """What Adam's first step (zero moments, bias-corrected) subtracts from a weight whose
    gradient is g: lr·g/(|g| + ε), ±lr but where |g| nears ε."""
    g = np.asarray(g, np.float64)
    return STEP_LR * g / (np.abs(g) + ADAM_EPS)


def _one_step_each(horse_torch, horse_model, horse, double):
    """One torch step and one engine step from the same batch, weights, noise and learning
    rate; returns the loss terms of both, and per variable (torch's state after the step,
    the engine's, torch's parameter or None for a running statistic, torch's gradient of rec +
    kl, the engine's)."""
    split = json.loads((horse_model / "split.json").read_text())
    dtype = torch.float64 if double else torch.float32
    model = MeshVAE.from_folder(horse_model, dtype=dtype) if double else copy.deepcopy(horse_torch)
    x = model.features(horse.positions[split["train"][:12]])
    assert x.dtype == dtype
    eps = torch.randn(len(x), model.latent, generator=torch.Generator().manual_seed(5))
    eps = eps.to(dtype)
    lr, betas = STEP_LR, (0.9, 0.95)
    terms, after, grads = _engine_step(model, x, eps, lr, betas, ADAM_EPS, double=double)
    model.train()
    before = {name: p.detach().clone() for name, p in model.named_parameters()}
    optimizer = torch.optim.Adam(model.parameters(), lr=lr, betas=betas, eps=ADAM_EPS)
    loss = model.loss(x, eps)
    optimizer.zero_grad()
    loss.total.backward()
    optimizer.step()
    params = dict(model.named_parameters())
    state = model.state_dict()
    assert set(after) == set(state) and set(grads) == set(params)
    variables = {}
    for name, want in after.items():
        assert want.dtype == (np.float64 if double else np.float32), (name, want.dtype)
        p = params.get(name)
        # torch's gradient holds the L2 term's w_l2 · θ, which the engine leaves to Adam.
        grad = None if p is None else p.grad.numpy() - model.loss_weights.l2 * before[name].numpy()
        variables[name] = (state[name].numpy(), want, p, grad, grads.get(name))
    return [float(t.detach()) for t in loss], terms, variables


@pytest.fixture(scope="module")
def float64_step(horse_torch, horse_model, horse):
    """The step of :func:`_one_step_each` in float64 on both sides: the reference the float32
    steps are measured against."""
    return _one_step_each(horse_torch, horse_model, horse, True)


def test_one_torch_step_equals_one_engine_step(horse_torch, horse_model, horse, float64_step):
    """The same batch, weights, noise and learning rate as one step of meshvae train's CPU
    engine, both in float32 (how each trains), each measured against the float64 step (where
    torch and the engine agree to 1e-5, below): the loss terms agree, each side's gradients are
    within float32 rounding of the float64 ones, and the weights after Adam's step agree but
    where Adam's first step differs for the two float32 gradients (it moves a weight by about
    ±lr whatever its gradient's size, so where the gradient is rounding noise, the noise
    decides).

    How close torch's float32 gradient comes depends on the BLAS torch calls, which meshvae does
    not choose: torch 2.15 with MKL on an AMD EPYC is 2.4e-4 off for enc.conv0.weight (the first
    convolution's, whose gradient is summed over 12 meshes × 8,431 vertices), where the engine
    is 7e-6 off. So torch is held to the worst case of a float32 sum
    of that length, n·2⁻²⁴ (6e-3), and the engine, whose sums meshvae controls, to 5e-5."""
    got_terms, terms, variables = _one_step_each(horse_torch, horse_model, horse, False)
    _, _, reference = float64_step
    worst_term = max(abs(g - w) / abs(w) for g, w in zip(got_terms, terms))
    assert worst_term < 1e-5, (got_terms, terms)
    l2 = horse_torch.loss_weights.l2
    start = {n: p.detach().numpy() for n, p in horse_torch.named_parameters()}  # before the step
    summed = 12 * horse.positions.shape[1]
    torch_bound = summed * 2.0**-24
    worst_torch = worst_engine = worst_weight = 0.0
    flipped = total = 0
    for name, (got, want, param, grad, want_grad) in variables.items():
        diff = np.abs(got - want)
        if param is None:  # batch norm's running statistics
            assert diff.max() < 1e-5, (name, diff.max())
            continue
        truth = reference[name][4]
        scale = np.abs(truth).max()
        torch_error = np.abs(grad - truth).max() / scale
        engine_error = np.abs(want_grad - truth).max() / scale
        worst_torch, worst_engine = max(worst_torch, torch_error), max(worst_engine, engine_error)
        assert torch_error < torch_bound, (name, torch_error)
        assert engine_error < 5e-5, (name, engine_error)
        # The two steps differ by what Adam's first step makes of the two float32 gradients
        # (the L2 term's w_l2·θ added, as both optimisers see it), and by nothing else.
        before = start[name]
        torch_step = _first_adam_step(grad + l2 * before)
        expected = np.abs(torch_step - _first_adam_step(want_grad + l2 * before))
        assert (np.abs(diff - expected) < 1e-5).all(), (name, np.abs(diff - expected).max())
        apart = expected >= 1e-5
        worst_weight = max(worst_weight, float(diff[~apart].max()))
        flipped += int(apart.sum())
        total += diff.size
    print(
        f"\nfloat32 step: loss terms {worst_term:.1e} (relative); gradients from float64's, "
        f"relative to each variable's largest: torch {worst_torch:.1e}, engine {worst_engine:.1e}; "
        f"weights {worst_weight:.1e} apart, {flipped} of {total} weights moved apart as their "
        f"float32 gradients' Adam steps differ"
    )


def test_one_float64_torch_step_equals_one_engine_step(float64_step):
    """The same step with both sides in float64 (the torch model and its operators, and the
    engine): every loss term to 1e-5 relative and every variable after the step to 1e-5, with
    no exception: without float32's rounding noise no gradient's sign is left to chance."""
    got_terms, terms, variables = float64_step
    worst_term = max(abs(g - w) / abs(w) for g, w in zip(got_terms, terms))
    assert worst_term < 1e-5, (got_terms, terms)
    worst_grad = worst_weight = 0.0
    total = 0
    for name, (got, want, param, grad, want_grad) in variables.items():
        diff = float(np.abs(got - want).max())
        worst_weight = max(worst_weight, diff)
        total += got.size
        assert diff < 1e-5, (name, diff)
        if param is not None:
            grad_error = np.abs(grad - want_grad).max() / np.abs(want_grad).max()
            worst_grad = max(worst_grad, grad_error)
            assert grad_error < 1e-5, (name, grad_error)
    print(
        f"\nfloat64 step: loss terms {worst_term:.1e} (relative), gradients {worst_grad:.1e} "
        f"(relative to each variable's largest), all {total} variables within "
        f"{worst_weight:.1e} after the step"
    )


# ---------------------------------------------------------------------------- other models


def train_synth(cli, root, *flags):
    root.mkdir(parents=True, exist_ok=True)
    mesh_set, model = root / "set", root / "model"
    if not mesh_set.is_dir():
        run_cli(cli, "synth", "--out", mesh_set, "--per-label", 3)
    run_cli(cli, "train", mesh_set, "--out", model, "--epochs", 2, "--batch", 4,
            "--latent", 16, "--quiet", *flags)
    return meshvae.load_set(mesh_set), model


@pytest.mark.parametrize(
    "flags",
    [
        ["--conditional"],
        ["--pool", "max", "--structure", "CPCPC", "--k", "4", "--channels", "12"],
        ["--pool", "graph", "--no-batch-norm", "--last-encoder-tanh"],
        ["--pool", "none", "--depool", "transpose"],
    ],
    ids=["conditional", "max-CPCPC-k4", "graph-no-bn", "none"],
)
def test_other_configurations_equal_the_rust_model(cli, tmp_path, flags):
    mesh_set, folder = train_synth(cli, tmp_path, *flags)
    model = MeshVAE.from_folder(folder)
    rust = meshvae.Model.load(folder)
    labels = mesh_set.labels if "--conditional" in flags else None
    mu_rust, sigma_rust = rust.encode(mesh_set.positions, labels=labels)
    with torch.no_grad():
        mu, sigma = model.encode(model.features(mesh_set.positions), labels=labels)
        x_hat = model.decode(torch.from_numpy(mu_rust), labels=labels)
    assert relative(mu, mu_rust) < 1e-5 and relative(sigma, sigma_rust) < 1e-5
    want = rust.decode(mu_rust, labels=labels)
    got = model.positions(x_hat)
    assert np.abs(centred(got) - centred(want)).max() / diagonal(want) < 1e-5
    if labels:
        with pytest.raises(ValueError, match="the model is conditional"):
            model.encode(model.features(mesh_set.positions))
        with pytest.raises(ValueError, match="not a label of this model"):
            model.one_hot(["nonsense"])


@pytest.mark.parametrize("net", ["coma", "spiralnet", "tan2018"])
def test_other_networks_are_refused(cli, tmp_path, net):
    _, folder = train_synth(cli, tmp_path, "--net", net)
    with pytest.raises(NotImplementedError, match=f"a {net} model .*meshvae.Model.load"):
        MeshVAE.from_folder(folder)
