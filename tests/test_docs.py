"""The documentation site (docs/, MkDocs): its generated parts come from the code, every page is in
the navigation, and the site builds offline with ``--strict`` (a broken link fails it).

The generated parts are made by docs/hooks/generated.py at build time; these tests call the same
functions.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import simcore
from simcore.cli import SUBCOMMANDS

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_generated", DOCS / "hooks" / "generated.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _hooks()


def page(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def test_every_scene_key_is_in_the_generated_reference_with_its_current_default():
    table = hooks.scene_keys_markdown().splitlines()
    for row in simcore.key_reference():
        line = next((ln for ln in table if ln.startswith(f"| `{row['key']}` |")), None)
        assert line is not None, row["key"]
        assert f"| {row['default']} |" in line
    assert "<!-- generated: scene-keys -->" in page("scene-files.md")


def test_the_cli_page_gives_every_commands_help():
    text = hooks.cli_markdown()
    for module in SUBCOMMANDS:
        name = module.__name__.rsplit(".", 1)[-1].replace("_", "-")
        assert f"## lmapd {name}\n" in text
        assert f"usage: lmapd {name}" in text
    assert "--version" in text
    assert "<!-- generated: cli -->" in page("cli.md")


def test_the_performance_page_comes_from_a_committed_bench_run_with_its_machine_and_date():
    fig = json.loads(hooks.BENCH_JSON.read_text(encoding="utf-8"))
    text = hooks.bench_markdown()
    assert fig["date_utc"] in text
    assert fig["machine"]["cpu"] in text
    for frame in fig["frames"]:
        assert f"| {frame['pixels']} x {frame['pixels']} | {frame['subrays']} |" in text
    assert "<!-- generated: bench -->" in page("performance.md")


def test_an_unknown_marker_fails_the_build():
    with pytest.raises(KeyError):
        hooks.on_page_markdown("<!-- generated: nothing -->", None, None, None)


def test_every_page_is_in_the_navigation():
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\s+- [^:]+: ([\w-]+\.md)$", config, re.MULTILINE))
    assert listed == {p.name for p in DOCS.glob("*.md")}


@pytest.mark.slow
def test_the_site_builds_offline_and_strict(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    cli = (tmp_path / "site" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "usage: lmapd simulate" in cli
    reference = (tmp_path / "site" / "reference" / "index.html").read_text(encoding="utf-8")
    assert "simcore.simulate" in reference
