"""The PyTorch example of python/README.md, run as written (from the folder holding the data
sets). Skips, saying so, where torch is not importable: CI does not install it."""

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def test_pytorch_example(horse_path, monkeypatch, capsys):
    pytest.importorskip(
        "torch", reason="SKIPPED: torch is not importable, so the README's PyTorch example is not run"
    )
    text = README.read_text()
    blocks = list(re.finditer(r"```python\n(.*?)```", text, re.S))
    assert len(blocks) == 1, "python/README.md should hold one python example"
    # Padded with the lines before it, so that tracebacks give the README's line numbers.
    code = "\n" * text[: blocks[0].start(1)].count("\n") + blocks[0].group(1)
    monkeypatch.chdir(horse_path.parent)
    exec(compile(code, str(README), "exec"), {})
    assert capsys.readouterr().out.strip() == "(8, 4216, 9) (8, 8431, 9)"
