"""The examples of python/README.md, run as written: the PyTorch pooling one (from the folder
holding the data sets), the meshvae.torch one (from a scratch folder where horse-gallop and a
model the command line trained are linked, since it writes a model folder; both skipped, saying
so, where torch is not importable: python/run-tests installs it) and the transform-matrices one
(from a scratch folder where horse-gallop is linked, since it writes transform.pkl into the
current folder)."""

import re
from pathlib import Path

import pytest

import meshvae

README = Path(__file__).resolve().parents[1] / "README.md"


def run_example(marker: str) -> None:
    """Runs the README's one python block containing `marker` in the current folder."""
    text = README.read_text()
    blocks = list(re.finditer(r"```python\n(.*?)```", text, re.S))
    assert len(blocks) == 3, "python/README.md should hold three python examples"
    (block,) = [b for b in blocks if marker in b.group(1)]
    # Padded with the lines before it, so that tracebacks give the README's line numbers.
    code = "\n" * text[: block.start(1)].count("\n") + block.group(1)
    exec(compile(code, str(README), "exec"), {})


def test_pytorch_example(horse_path, monkeypatch, capsys):
    pytest.importorskip(
        "torch", reason="SKIPPED: torch is not importable, so the README's PyTorch example is not run"
    )
    monkeypatch.chdir(horse_path.parent)
    run_example("def to_torch")
    assert capsys.readouterr().out.strip() == "(8, 4216, 9) (8, 8431, 9)"


def test_meshvae_torch_example(horse_path, horse_model, tmp_path, monkeypatch, capsys):
    torch = pytest.importorskip(
        "torch", reason="SKIPPED: torch is not importable, so the README's meshvae.torch example is not run"
    )
    (tmp_path / "horse-gallop").symlink_to(horse_path, target_is_directory=True)
    (tmp_path / "horse-model").symlink_to(horse_model, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # see test_torch.py: two threads crawl on a shared 2-core machine
    try:
        run_example("meshvae.torch")
    finally:
        torch.set_num_threads(threads)
    assert capsys.readouterr().out.strip() == "(2, 128) (2, 8431, 3)"
    tuned = meshvae.Model.load(tmp_path / "horse-model-tuned")
    assert tuned.latent == 128


def test_transform_matrices_example(horse_path, tmp_path, monkeypatch, capsys):
    (tmp_path / "horse-gallop").symlink_to(horse_path, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    run_example("meshvae.sampling")
    assert capsys.readouterr().out.splitlines() == [
        "[8431, 2108, 527, 132, 33]",
        "['adj', 'down_transform', 'face', 'up_transform', 'vertices'] (2108, 8431) 25293",
    ]
    assert (tmp_path / "transform.pkl").is_file()
