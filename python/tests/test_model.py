"""Model.load / encode / decode of models the command line trains on its synthetic set: the
decoded means equal what `meshvae reconstruct` writes."""

import numpy as np
import pytest

import meshvae
from conftest import run_cli

LATENT = 16


def train(cli, root, *flags):
    """The synthetic set (6 meshes, 2 labels) and a tiny model trained on it."""
    root.mkdir(parents=True, exist_ok=True)
    mesh_set, model = root / "set", root / "model"
    if not mesh_set.is_dir():
        run_cli(cli, "synth", "--out", mesh_set, "--per-label", 3)
    run_cli(
        cli, "train", mesh_set, "--out", model, "--epochs", 2, "--batch", 4,
        "--latent", LATENT, "--quiet", *flags,
    )
    return mesh_set, model


@pytest.fixture(scope="module")
def trained(cli, tmp_path_factory):
    return train(cli, tmp_path_factory.mktemp("model"))


@pytest.fixture(scope="module")
def model(trained):
    return meshvae.Model.load(trained[1])


def cli_reconstructions(cli, model_dir, names, out):
    run_cli(cli, "reconstruct", model_dir, "--all", "--out", out)
    return np.stack([meshvae.load_mesh(out / f"{name}.obj")[0] for name in names])


def aligned(decoded, originals):
    """Decoded meshes moved onto their originals' centroids, as `meshvae reconstruct` writes
    them (the decoder fixes a shape only up to a translation)."""
    decoded = np.asarray(decoded, dtype=np.float64)
    shift = np.asarray(originals, dtype=np.float64).mean(axis=-2) - decoded.mean(axis=-2)
    return decoded + shift[..., None, :]


def assert_same_meshes(got, want):
    diagonal = np.linalg.norm(want.reshape(-1, 3).max(0) - want.reshape(-1, 3).min(0))
    error = np.abs(got - want).max() / diagonal
    assert error < 1e-5, f"max difference {error:.2e} of the bounding box diagonal"


def test_load_and_properties(model, trained):
    mesh_set = meshvae.load_set(trained[0])
    assert model.latent == LATENT
    assert model.vertex_count == mesh_set.vertex_count
    np.testing.assert_array_equal(model.faces, mesh_set.faces)
    assert model.template.shape == (mesh_set.vertex_count, 3)
    assert model.template.dtype == np.float32
    config = model.config
    assert config["model"]["latent"] == LATENT
    assert config["vertices"] == mesh_set.vertex_count
    assert config["names"] == mesh_set.names
    assert model.labels == []
    assert "latent=16" in repr(model)


def test_encode_decode_equals_cli_reconstruct(cli, model, trained, tmp_path):
    mesh_set = meshvae.load_set(trained[0])
    mu, sigma = model.encode(mesh_set.positions)
    n = len(mesh_set.names)
    assert mu.shape == sigma.shape == (n, LATENT)
    assert mu.dtype == sigma.dtype == np.float32
    assert np.isfinite(mu).all() and np.isfinite(sigma).all() and (sigma > 0).all()

    decoded = model.decode(mu)
    assert decoded.shape == (n, mesh_set.vertex_count, 3) and decoded.dtype == np.float32
    want = cli_reconstructions(cli, trained[1], mesh_set.names, tmp_path / "r")
    assert_same_meshes(aligned(decoded, mesh_set.positions), want)

    # One mesh and one vector: [V, 3] -> [latent] -> [V, 3]; float64 input is accepted.
    mu2, sigma2 = model.encode(mesh_set.positions[2].astype(np.float64))
    assert mu2.shape == sigma2.shape == (LATENT,)
    np.testing.assert_allclose(mu2, mu[2], rtol=1e-5, atol=1e-6)
    one = model.decode(mu2)
    assert one.shape == (mesh_set.vertex_count, 3)
    assert_same_meshes(aligned(one, mesh_set.positions[2]), want[2])


def test_conditional_model(cli, tmp_path):
    mesh_set_dir, model_dir = train(cli, tmp_path, "--conditional")
    mesh_set = meshvae.load_set(mesh_set_dir)
    model = meshvae.Model.load(model_dir)
    assert sorted(model.labels) == sorted(set(mesh_set.labels))
    mu, sigma = model.encode(mesh_set.positions, labels=mesh_set.labels)
    assert mu.shape == (len(mesh_set.names), LATENT) and (sigma > 0).all()
    decoded = model.decode(mu, labels=mesh_set.labels)
    want = cli_reconstructions(cli, model_dir, mesh_set.names, tmp_path / "r")
    assert_same_meshes(aligned(decoded, mesh_set.positions), want)
    with pytest.raises(meshvae.InputError, match="labels: the model is conditional"):
        model.encode(mesh_set.positions)
    with pytest.raises(meshvae.InputError, match="labels: 1 labels for 6 rows"):
        model.decode(mu, labels=mesh_set.labels[:1])
    with pytest.raises(meshvae.InputError, match="nonsense"):
        model.decode(mu[:1], labels=["nonsense"])


def test_bad_input(model, trained):
    v = model.vertex_count
    with pytest.raises(meshvae.InputError, match=rf"positions: expected shape \[N, {v}, 3\] or \[{v}, 3\]"):
        model.encode(np.zeros((2, v - 1, 3), np.float32))
    with pytest.raises(meshvae.InputError, match="positions: expected a float32 or float64 array"):
        model.encode(np.zeros((v, 3), np.int32))
    with pytest.raises(meshvae.InputError, match=rf"z: expected shape \[N, {LATENT}\] or \[{LATENT}\]"):
        model.decode(np.zeros((3, LATENT + 1), np.float32))
    with pytest.raises(meshvae.InputError, match="z: row 1 is not finite"):
        model.decode(np.array([[0.0] * LATENT, [np.nan] * LATENT]))
    with pytest.raises(meshvae.InputError, match="labels: the model is not conditional"):
        model.decode(np.zeros(LATENT), labels=["a"])


def test_missing_or_foreign_folder(tmp_path, trained):
    with pytest.raises(meshvae.FileError, match="no such model folder"):
        meshvae.Model.load(tmp_path / "absent")
    with pytest.raises(meshvae.InputError, match="not a model folder"):
        meshvae.Model.load(trained[0])  # the mesh set, not a model


def test_encode_decode_equals_cli_reconstruct_on_horse_gallop(cli, horse_path, tmp_path):
    """The same on real data: a one-epoch horse-gallop model (far from trained; the
    comparison is of the two code paths, not of the model), its test meshes."""
    model_dir = tmp_path / "horse-model"
    run_cli(cli, "train", horse_path, "--out", model_dir, "--epochs", 1, "--quiet")
    model = meshvae.Model.load(model_dir)
    horse = meshvae.load_set(horse_path)
    out = tmp_path / "r"
    run_cli(cli, "reconstruct", model_dir, "--out", out)
    names = sorted(p.stem for p in out.glob("*.obj"))
    assert len(names) == 24, names
    index = {name.rsplit(".", 1)[0]: i for i, name in enumerate(horse.names)}
    ids = [index[name] for name in names]
    want = np.stack([meshvae.load_mesh(out / f"{name}.obj")[0] for name in names])
    mu, _ = model.encode(horse.positions[ids])
    assert_same_meshes(aligned(model.decode(mu), horse.positions[ids]), want)


def test_every_safetensors_file_reads_with_the_safetensors_package(trained, tmp_path):
    """Any safetensors reader opens what a model folder holds, the metadata follows one
    convention, names the tied decoder weight and explains the checkpoint's counters; the
    checkpoint does not repeat the weights."""
    import zlib

    from safetensors import safe_open

    files = sorted(trained[1].glob("*.safetensors"))
    names = {f.name for f in files}
    wanted = {"weights.safetensors", "checkpoint.safetensors", "hierarchy.safetensors"}
    assert wanted <= names, names
    formats = ("meshvae-weights", "meshvae-checkpoint", "meshvae-hierarchy")
    with safe_open(trained[1] / "weights.safetensors", "np") as f:
        weights_epoch = int(f.metadata()["epoch"])
    for path in files:
        with safe_open(path, "np") as f:
            meta = f.metadata()
            assert meta["format"] in formats, path
            assert int(meta["version"]) >= 2 and meta["writer"].startswith("meshvae ")
            data = path.read_bytes()
            header = int.from_bytes(data[:8], "little")
            assert meta["checksum"] == f"crc32:{zlib.crc32(data[8 + header:]):08x}", path
            for key in f.keys():
                assert f.get_tensor(key).size > 0, (path, key)
            if meta["format"] == "meshvae-hierarchy":
                assert "levels" in meta["hierarchy"] and "level.0.laplacian.values" in f.keys()
            elif meta["format"] == "meshvae-weights":
                assert "dec.fc.weight" in meta["tied"] and "enc.mu.weight" in meta["tied"]
                assert "dec.fc.weight" not in f.keys() and "enc.mu.weight" in f.keys()
                assert "layout" in meta and "config" in meta
            else:
                keys = list(f.keys())
                assert not any(k.startswith("adam.adam.") for k in keys), keys
                assert "progress.epochs_done" in keys and "progress.epochs_done" in meta["progress"]
                # The best epoch's state; its weights are weights.safetensors, not repeated.
                assert not any(k.startswith("model.") for k in keys), keys
                assert int(f.get_tensor("progress.epochs_done")[0]) == weights_epoch


@pytest.mark.parametrize("net", ["coma", "spiralnet", "tan2018"])
def test_other_networks_encode_and_decode_as_the_cli_reconstructs(cli, tmp_path, net):
    """The networks `meshvae train --net` trains load and run as ours: a position network's
    posterior is the point mu (sigma 0), and its decoder gives positions directly."""
    mesh_set_dir, model_dir = train(cli, tmp_path, "--net", net)
    mesh_set = meshvae.load_set(mesh_set_dir)
    model = meshvae.Model.load(model_dir)
    assert model.config["model"]["net"] == net
    mu, sigma = model.encode(mesh_set.positions)
    assert mu.shape == (len(mesh_set.names), LATENT)
    if net == "tan2018":
        assert (sigma > 0).all()
    else:
        assert (sigma == 0).all()
    decoded = model.decode(mu)
    want = cli_reconstructions(cli, model_dir, mesh_set.names, tmp_path / "r")
    assert_same_meshes(aligned(decoded, mesh_set.positions), want)
