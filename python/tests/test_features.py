"""ACAP features, their normalisation and their inverse."""

import numpy as np
import pytest

import meshvae
from conftest import run_cli


def rms_rel(reconstructed, original):
    """The command line's `roundtrip` error: per-vertex distances after aligning centroids,
    each frame's divided by its bounding-box diagonal, RMS over all vertices of all frames."""
    a = reconstructed.astype(np.float64)
    b = original.astype(np.float64)
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    diagonal = np.linalg.norm(original.max(axis=1) - original.min(axis=1), axis=1)
    d2 = ((a - b) ** 2).sum(axis=2) / diagonal[:, None] ** 2
    return float(np.sqrt(d2.mean()))


def test_horse_features_equal_the_command_line(cli, horse_path, horse_features, tmp_path):
    assert horse_features.shape == (48, 8431, 9) and horse_features.dtype == np.float32
    raw = tmp_path / "raw.safetensors"
    run_cli(cli, "features", horse_path, "--out", raw, "--raw")
    stored = meshvae.load_features(raw)
    assert not stored.normalized and stored.names[0] == "0001"
    np.testing.assert_array_equal(stored.features, horse_features)
    # The normalisation the command stores is Normalization.fit of the same features, and the
    # normalised file holds Normalization.apply of them.
    assert stored.normalization == meshvae.Normalization.fit(horse_features)
    normalized = tmp_path / "normalized.safetensors"
    run_cli(cli, "features", horse_path, "--out", normalized)
    stored = meshvae.load_features(normalized)
    assert stored.normalized
    np.testing.assert_array_equal(stored.features, stored.normalization.apply(horse_features))


def test_horse_rest_frame_is_the_identity(horse_features):
    identity = np.array([0, 0, 0, 1, 0, 0, 1, 0, 1], np.float32)
    np.testing.assert_allclose(horse_features[0], np.broadcast_to(identity, (8431, 9)), atol=1e-6)


def test_horse_round_trip_within_the_command_lines_error(horse, horse_features):
    # What `meshvae roundtrip` does: normalise, store as f32, invert, reconstruct. Its error on
    # horse-gallop is 1.3e-8 of the diagonal; the Rust test of the same path allows 1e-6.
    norm = meshvae.Normalization.fit(horse_features)
    stored = norm.apply(horse_features)
    assert np.abs(stored).max() <= 0.95 + 1e-6
    rec = meshvae.reconstruct(norm.invert(stored), horse.positions[0], horse.faces)
    assert rec.shape == (48, 8431, 3) and rec.dtype == np.float32
    error = rms_rel(rec, horse.positions)
    assert error < 1e-6, error
    # One frame as [V, 9] gives [V, 3].
    one = meshvae.reconstruct(horse_features[5], horse.positions[0], horse.faces)
    np.testing.assert_allclose(one, rec[5], atol=1e-5)


def test_options_and_rest_frame(sphere_set):
    exact = meshvae.acap_features(sphere_set)
    rec = meshvae.reconstruct(exact, sphere_set.positions[0], sphere_set.faces)
    assert rms_rel(rec, sphere_set.positions) < 1e-6
    plain = meshvae.acap_features(sphere_set, integrable=False)
    assert not np.array_equal(plain, exact)
    by_name = meshvae.acap_features(sphere_set, rest="2")
    np.testing.assert_array_equal(by_name, meshvae.acap_features(sphere_set, rest=2))
    rec = meshvae.reconstruct(by_name, sphere_set.positions[2], sphere_set.faces)
    assert rms_rel(rec, sphere_set.positions) < 1e-6
    with pytest.raises(meshvae.InputError, match='rest: no frame "nine"'):
        meshvae.acap_features(sphere_set, rest="nine")
    with pytest.raises(meshvae.InputError, match="rest: frame 7 is beyond"):
        meshvae.acap_features(sphere_set, rest=7)


def test_normalization(sphere_set):
    f = meshvae.acap_features(sphere_set)
    n = meshvae.Normalization.fit(f)
    y = n.apply(f)
    assert y.shape == f.shape and y.dtype == np.float32
    assert -0.95 - 1e-6 <= y.min() and y.max() <= 0.95 + 1e-6
    np.testing.assert_allclose(n.invert(y), f, atol=1e-5)
    # Any leading shape, as long as the last axis is the 9 features.
    np.testing.assert_array_equal(n.apply(f[1, :10]), y[1, :10])
    back = meshvae.Normalization.from_json(n.to_json())
    assert back == n and n.clamp is None
    q = meshvae.Normalization.fit(f, quantile=0.01)
    assert q.clamp == 1.0 and np.abs(q.apply(f)).max() <= 1.0
    made = meshvae.Normalization(-1.0, 1.0, 0.0, 2.0)
    np.testing.assert_allclose(made.apply(np.zeros((1, 9))), [[0.0] * 3 + [-0.95] * 6])
    with pytest.raises(meshvae.InputError, match="max > min"):
        meshvae.Normalization(1.0, -1.0, 0.0, 2.0)
    with pytest.raises(meshvae.InputError, match=r"features: expected an array of shape \[\.\.\., 9\]"):
        n.apply(np.zeros((4, 8), np.float32))


def test_long_calls_release_the_gil(horse):
    import threading
    import time

    ticks, done = [0], threading.Event()

    def count():
        while not done.is_set():
            ticks[0] += 1
            time.sleep(0.001)

    thread = threading.Thread(target=count)
    thread.start()
    try:
        meshvae.acap_features(horse)
    finally:
        done.set()
        thread.join()
    # With the GIL held for the whole call the counter could not run at all.
    assert ticks[0] > 10, ticks[0]
