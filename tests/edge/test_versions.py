"""``--version`` on every command; a LICENSE file matching pyproject's licence."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from edge.provenance import package_version

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = {
    "depthseg-sim": "sim.cli", "depthseg-train": "edge.train_cli", "depthseg-eval": "edge.eval_cli",
    "depthseg-tune": "edge.tune_cli", "depthseg-export": "export.cli", "depthseg-bench": "export.bench_cli",
    "depthseg-replay": "replay.cli",
}


def test_every_console_script_is_covered():
    text = (ROOT / "pyproject.toml").read_text()  # no tomllib on Python 3.10
    section = text.split("[project.scripts]", 1)[1].split("\n[", 1)[0]
    scripts = {line.split("=")[0].strip() for line in section.splitlines() if "=" in line}
    assert scripts == set(COMMANDS)


@pytest.mark.parametrize("prog", sorted(COMMANDS))
def test_version(prog, capsys):
    mod = importlib.import_module(COMMANDS[prog])
    with pytest.raises(SystemExit) as e:
        mod.main(["--version"])
    assert e.value.code == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith(f"{prog} (depthseg) {package_version()}")


def test_license_file_is_mit_like_pyproject():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Permission is hereby granted" in text
    assert 'license = { text = "MIT" }' in (ROOT / "pyproject.toml").read_text()
