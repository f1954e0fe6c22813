"""The package as a user installs it (issue 29): a wheel built offline from the sources, installed
into a fresh virtual environment, runs ``lmapd`` from an empty folder, the built-in targets and the
paper scene found inside the installed package (``simcore.assets``), never in the checkout.

The fresh environment sees the project's dependencies through one ``.pth`` line naming this
interpreter's site-packages (a line adds a folder to ``sys.path``; the ``.pth`` files inside that
folder, the editable install's among them, are not run), so nothing is downloaded.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
import urllib.request
import zipfile
from pathlib import Path

import pytest
from support.launch import free_port

from app.logic.lessons import LESSONS_DIR
from app.ui import static

ROOT = Path(__file__).resolve().parent.parent
# what the build reads: the packaging files, the README (the long description), the license, the
# packages and the assets mapped into simcore.assets
SOURCES = ("pyproject.toml", "setup.py", "README.md", "LICENSE", "simcore", "app", "assets")

pytestmark = pytest.mark.slow  # one wheel built and installed, lmapd run from it: 30-45 s


def build_wheel(out_dir: Path, work_dir: Path) -> Path:
    """The wheel built offline (no index, no build isolation) from a copy of the sources."""
    src = work_dir / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=ignore)
        else:
            shutil.copy2(path, src / name)
    pip = [sys.executable, "-m", "pip"]
    subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(out_dir), "."],
        cwd=src,
        check=True,
        capture_output=True,
        text=True,
    )
    (wheel,) = out_dir.glob("lmapd_sim-*.whl")
    return wheel


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A fresh venv with the wheel installed (no dependencies): (its bin folder, the wheel)."""
    work = tmp_path_factory.mktemp("wheel")
    wheel = build_wheel(work / "dist", work)
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    deps = sysconfig.get_paths()["purelib"]
    Path(purelib, "project_dependencies.pth").write_text(deps + "\n", encoding="utf-8")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index"]
        + ["--quiet", str(wheel)],
        check=True,
        capture_output=True,
        text=True,
    )
    return venv / "bin", wheel


def run_in(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    """``argv`` run in ``folder`` with no PYTHONPATH (the checkout must not be reachable)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        argv, cwd=folder, env=env, capture_output=True, text=True, timeout=120, check=False
    )


def test_wheel_carries_the_assets_the_license_and_the_credits(installed):
    _, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    for target in ("aqua", "kepler", "mro", "sentinel6", "tdrs", "tess"):
        folder = f"simcore/assets/targets/{target}/"
        for file in (f"{target}.glb", "target.toml", "materials.toml", "README.md"):
            assert folder + file in names
    assert "simcore/assets/scenes/paper.toml" in names
    assert "simcore/assets/material_rules.toml" in names
    assert "simcore/assets/sweeps/example.toml" in names
    assert "simcore/py.typed" in names
    assert "simcore/data/astm_e490_am0_900_1700nm.csv" in names  # the Sun's spectrum
    assert "app/ui/layout.py" in names
    for page_file in (*static.SCRIPTS, *static.STYLES):  # the page's scripts and styles
        assert f"app/static/{page_file}" in names
    for lesson in LESSONS_DIR.glob("*.toml"):  # the lessons
        assert f"simcore/assets/lessons/{lesson.name}" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)


def test_installed_wheel_simulates_from_an_empty_folder(installed, tmp_path):
    bin_dir, _ = installed
    where = run_in(
        tmp_path,
        str(bin_dir / "python"),
        "-c",
        "import simcore, simcore.scene as s; print(simcore.__file__); print(s.SCENES_DIR)",
    )
    assert where.returncode == 0, where.stderr
    module_file, scenes_dir = where.stdout.split()
    venv = bin_dir.parent
    assert Path(module_file).is_relative_to(venv)  # the installed package, not the checkout
    assert Path(scenes_dir).is_relative_to(venv)

    done = run_in(
        tmp_path,
        str(bin_dir / "lmapd"),
        "simulate",
        "--set",
        "pixels=32",
        "--out",
        "cloud.ply",
        "--summary",
        "summary.json",
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert summary["n_pixels"] == 32 * 32
    assert summary["n_points"] > 0
    assert (tmp_path / "cloud.ply").stat().st_size > 0


def test_installed_wheel_lists_targets_and_answers_each_command(installed, tmp_path):
    bin_dir, _ = installed
    lmapd = str(bin_dir / "lmapd")
    targets = run_in(tmp_path, lmapd, "targets")
    assert targets.returncode == 0, targets.stderr
    for name in ("aqua", "kepler", "mro", "sentinel6", "tdrs", "tess"):
        assert name in targets.stdout
    version = run_in(tmp_path, lmapd, "--version")
    assert version.returncode == 0, version.stderr
    assert version.stdout.split() == ["lmapd", metadata_version()]
    for command in ("reproduce", "app"):
        helped = run_in(tmp_path, lmapd, command, "--help")
        assert helped.returncode == 0, helped.stderr
        assert f"usage: lmapd {command}" in helped.stdout


def metadata_version() -> str:
    """The version the checkout declares (pyproject reads it from simcore/_version.py)."""
    from simcore._version import __version__

    return __version__


def test_installed_wheel_serves_the_app(installed, tmp_path):
    """``lmapd app`` from the installed package prints its address and serves the page there."""
    bin_dir, _ = installed
    port = free_port()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    server = subprocess.Popen(
        [str(bin_dir / "lmapd"), "app", "--port", str(port), "--no-spare"],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        address, printed = None, []
        while address is None and time.monotonic() < deadline:
            line = server.stdout.readline()
            if not line:  # the server ended
                break
            printed.append(line)
            found = re.search(r"(http://127\.0\.0\.1:\d+/\?token=\S+)", line)
            address = found.group(1) if found else None
        assert address is not None, f"no address printed: {''.join(printed)}"
        with urllib.request.urlopen(address, timeout=60) as page:  # the launcher starts a session
            assert page.status == 200
            assert b"<html" in page.read().lower()
    finally:
        server.send_signal(signal.SIGTERM)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
