"""The README stays a front door: short, the two commands on its first screen, and every command it
shows runs. The commands of the documentation pages (docs/) are checked against the parser here
too; the pages' generated parts and their build are tests/test_docs.py's.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from simcore.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
PAGES = sorted((ROOT / "docs").glob("*.md"))
LMAPD = re.compile(r"^(?:\.venv/bin/)?lmapd\s")


def shell_lines(text: str) -> list[str]:
    """Each line of the ```sh blocks of ``text``, its trailing comment dropped."""
    lines = []
    for block in re.findall(r"```sh\n(.*?)```", text, re.DOTALL):
        for line in block.splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line:
                lines.append(line)
    return lines


def lmapd_commands(text: str) -> list[list[str]]:
    """The ``lmapd`` commands of ``text``'s shell blocks, as argument lists (without ``lmapd``)."""
    return [shlex.split(line)[1:] for line in shell_lines(text) if LMAPD.match(line)]


def test_the_readme_is_at_most_250_lines():
    assert len(README.splitlines()) <= 250


def test_the_first_screen_gives_the_two_commands():
    first_screen = "\n".join(README.splitlines()[:25])
    assert "make app" in first_screen and "make test" in first_screen
    assert "make app PORT=" in README and "make app HOST=" in README


def test_the_readme_credits_nasa_for_the_mro_model():
    assert "Courtesy NASA/JPL-Caltech" in README


def test_every_make_command_shown_is_a_makefile_target():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    targets = set(re.findall(r"^([a-z][\w-]*):", makefile, re.MULTILINE))
    for text in [README] + [p.read_text(encoding="utf-8") for p in PAGES]:
        for line in shell_lines(text):
            if line.startswith("make "):
                target = line.split()[1]
                assert target in targets, line


def test_every_link_of_the_readme_to_a_file_of_the_repository_exists():
    for link in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README):
        if not link.startswith("http"):
            assert (ROOT / link).exists(), link


@pytest.mark.parametrize("page", ["README.md"] + [f"docs/{p.name}" for p in PAGES])
def test_every_lmapd_command_shown_is_one_the_parser_accepts(page):
    parser = build_parser()
    for argv in lmapd_commands((ROOT / page).read_text(encoding="utf-8")):
        if "--help" in argv or "-h" in argv or any(a.startswith("[") for a in argv):
            continue  # help, or a usage line ("--out DIR [--quick]")
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{page}: lmapd {shlex.join(argv)} is refused by the parser ({exc})")


def test_the_readme_shows_the_commands_of_each_quick_start():
    commands = {argv[0] for argv in lmapd_commands(README)}
    assert {"simulate", "sweep", "compare", "keys"} <= commands
    assert "import simcore" in README


@pytest.mark.slow
def test_every_lmapd_command_of_the_readme_runs(tmp_path):
    """Each runs as shown, from a folder where ``assets/`` is the repository's (sweep example)."""
    (tmp_path / "assets").symlink_to(ROOT / "assets")
    lmapd = Path(sys.executable).with_name("lmapd")
    for argv in lmapd_commands(README):
        done = subprocess.run(
            [str(lmapd), *argv],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
            env={**os.environ, "COLUMNS": "100"},
            check=False,
        )
        assert done.returncode == 0, f"lmapd {shlex.join(argv)}: {done.stderr}"
        for option in ("--out", "--summary", "--waveforms"):
            if option in argv:
                assert (tmp_path / argv[argv.index(option) + 1]).exists(), (argv, option)


@pytest.mark.slow
def test_the_python_quick_start_runs(capsys):
    (code,) = re.findall(r"```python\n(.*?)```", README, re.DOTALL)
    exec(compile(code, "README.md", "exec"), {})
    printed = capsys.readouterr().out.split()
    assert printed[::2] == ["3", "4", "5", "6"]
