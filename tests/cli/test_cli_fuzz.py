"""Hypothesis-generated scene files: `lmapd simulate` gives a result or one clear error line,
never a traceback, and never a half-written output."""

import dataclasses
import os
from pathlib import Path

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simcore import cli
from simcore.scene import SECTIONS

KEYS = [(s, f.name) for s, cls in SECTIONS.items() for f in dataclasses.fields(cls)]
SCALARS = st.one_of(
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.booleans(),
    st.lists(st.floats(-1e3, 1e3), max_size=4),
    st.dictionaries(st.text(max_size=5), st.text(max_size=5), max_size=2),
)


@st.composite
def scene_tables(draw):
    data: dict = {"detector": {"pixels": draw(st.integers(1, 24))}}
    for section, name in draw(st.lists(st.sampled_from(KEYS), max_size=4)):
        data.setdefault(section, {})[name] = draw(SCALARS)
    if draw(st.booleans()):
        data[draw(st.sampled_from(["seed", "conventions", "preset", "bogus", "paper_forms"]))] = (
            draw(SCALARS)
        )
    return data


def toml_text(data) -> str:
    try:
        return tomli_w.dumps(data)
    except (TypeError, ValueError):  # NaN in a list etc.: write a deliberately malformed file
        return "[detector\npixels = 8\n"


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=scene_tables())
def test_any_scene_file_gives_a_result_or_one_clear_error(tmp_path_factory, data, capsys):
    folder = tmp_path_factory.mktemp("fuzz")
    scene = folder / "scene.toml"
    scene.write_text(toml_text(data))
    out = folder / "cloud.ply"
    code = cli.main(["simulate", str(scene), "--out", str(out), "--set", "fidelity.subrays=1"])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    if code == 0:
        assert out.exists()
    else:
        assert code == 2
        assert captured.err.startswith("lmapd: error: ") and len(captured.err.splitlines()) == 1
        assert not out.exists()
    assert not [p for p in folder.iterdir() if p.name.endswith(".part")]


# ----------------------------------------------------------------------------------------------
# issue 20: each hostile input ends in one line naming the key or file, exit 2, nothing written
# ----------------------------------------------------------------------------------------------
SMALL = ["--set", "pixels=16", "--set", "fidelity.subrays=1"]


def _one_clear_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("lmapd: error: ") and "\n" not in err, err
    assert "internal error" not in err and "Traceback" not in err
    return err


def _visible(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


@pytest.mark.parametrize("name", ["Ré-entrée 航天器", "two\nlines", "tab\there"])
def test_a_scene_name_in_any_script_or_with_a_newline_works_in_every_cloud_format(
    tmp_path, capsys, name
):
    scene = tmp_path / "s.toml"
    scene.write_text(tomli_w.dumps({"name": name}), encoding="utf-8")
    for suffix in (".ply", ".las"):
        out = tmp_path / f"c{suffix}"
        argv = ["simulate", str(scene), "--out", str(out), "--summary", str(tmp_path / "s.json")]
        assert cli.main([*argv, *SMALL]) == 0, capsys.readouterr().err
    header = (tmp_path / "c.ply").read_bytes().split(b"end_header")[0].decode("ascii")
    escaped = name.encode("unicode_escape").decode("ascii")  # R\\xe9-entr..., two\\nlines
    assert f"comment scene {escaped}\n" in header
    from simcore.io import read_cloud_comments

    assert f"scene {escaped}" in read_cloud_comments(tmp_path / "c.las")


def test_a_mesh_file_with_a_non_ascii_name_gives_a_ply(tmp_path, capsys):
    mesh = tmp_path / "plaque-é 板.obj"
    mesh.write_text("v -5 -5 0\nv 5 -5 0\nv 5 5 0\nv -5 5 0\nf 1 2 3\nf 1 3 4\n", encoding="utf-8")
    out = tmp_path / "c.ply"
    argv = ["simulate", "--set", f"target.mesh={mesh}", "--out", str(out), *SMALL]
    assert cli.main(argv) == 0, capsys.readouterr().err
    header = out.read_bytes().split(b"end_header")[0].decode("ascii")
    assert "plaque-\\xe9 \\u677f" in header


def _deep_toml(tmp_path):
    p = tmp_path / "deep.toml"
    p.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n", encoding="utf-8")
    return p


def _big_file(tmp_path):
    p = tmp_path / "big.toml"
    p.write_bytes(b"# " + b"x" * (5 * 2**20) + b"\n")
    return p


@pytest.mark.parametrize(
    "make, expected",
    [
        (_deep_toml, "nested too deeply"),
        (lambda tmp: tmp, "is a folder"),
        (lambda tmp: Path("/dev/zero"), "larger than 4 MiB"),
        (_big_file, "larger than 4 MiB"),
        (lambda tmp: tmp / ("n" * 10_000_000), "scene file not found"),
    ],
    ids=["nested-5000", "a-folder", "dev-zero", "5-MB", "10-MB-path"],
)
def test_a_hostile_scene_file_gives_one_line_naming_it(tmp_path, capsys, make, expected):
    scene = make(tmp_path)
    out = tmp_path / "out" / "c.ply"
    out.parent.mkdir()
    assert cli.main(["simulate", str(scene), "--out", str(out), *SMALL]) == 2
    err = _one_clear_line(capsys)
    assert expected in err and len(err) < 1000
    assert _visible(out.parent) == []


@pytest.mark.parametrize(
    "make, expected",
    [
        (_deep_toml, "nested too deeply"),
        (lambda tmp: tmp, "is a folder"),
        (lambda tmp: Path("/dev/zero"), "larger than 4 MiB"),
    ],
    ids=["nested-5000", "a-folder", "dev-zero"],
)
def test_a_hostile_material_map_gives_one_line_naming_it(tmp_path, capsys, make, expected):
    out = tmp_path / "out" / "c.ply"
    out.parent.mkdir()
    argv = ["simulate", "--set", f"target.material_map={make(tmp_path)}", "--out", str(out)]
    assert cli.main([*argv, *SMALL]) == 2
    err = _one_clear_line(capsys)
    assert "material_map" in err and expected in err
    assert _visible(out.parent) == []


@pytest.mark.parametrize("dt", ["1e-30", "1e-14", "1e-12", "4e-12"])
def test_a_time_step_too_fine_for_memory_or_time_is_refused_naming_the_key(tmp_path, capsys, dt):
    out = tmp_path / "c.ply"
    assert cli.main(["simulate", "--set", f"fidelity.time_step_s={dt}", "--out", str(out)]) == 2
    err = _one_clear_line(capsys)
    assert "fidelity.time_step_s" in err and "10 ps" in err
    assert not out.exists()


def test_the_finest_time_step_in_range_runs(tmp_path, capsys):
    out = tmp_path / "c.ply"
    argv = ["simulate", "--set", "fidelity.time_step_s=1e-11", "--out", str(out), *SMALL]
    assert cli.main(argv) == 0, capsys.readouterr().err


@pytest.mark.parametrize(
    "option, where",
    [
        ("--out", lambda tmp: "/proc/lmapd-test.ply"),  # a read-only place, even for root
        ("--out", lambda tmp: str(tmp / "folder.ply")),  # onto a folder
        ("--out", lambda tmp: str(tmp / "file.txt" / "c.ply")),  # under a file
        ("--summary", lambda tmp: "/proc/lmapd-test.json"),
        ("--waveforms", lambda tmp: str(tmp / "file.txt" / "w.npz")),
    ],
    ids=["out-read-only", "out-onto-folder", "out-under-file", "summary-read-only", "wave-under"],
)
def test_an_unwritable_output_is_refused_before_any_work_and_nothing_is_written(
    tmp_path, capsys, option, where
):
    (tmp_path / "folder.ply").mkdir()
    (tmp_path / "file.txt").write_text("x")
    paths = {"--out": str(tmp_path / "c.ply"), "--summary": str(tmp_path / "s.json")}
    paths["--waveforms"] = str(tmp_path / "w.npz")
    paths[option] = where(tmp_path)
    argv = ["simulate", *SMALL]
    for opt, path in paths.items():
        argv += [opt, path]
    assert cli.main(argv) == 2
    err = _one_clear_line(capsys)
    assert option in err
    assert _visible(tmp_path) == ["file.txt", "folder.ply"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_huge_bad_value_is_quoted_in_at_most_a_few_hundred_characters(tmp_path, capsys):
    value = "9" * 10_000_000 + "x"
    out = tmp_path / "c.ply"
    assert cli.main(["simulate", "--set", f"pitch_deg={value}", "--out", str(out)]) == 2
    err = _one_clear_line(capsys)
    assert "pitch_deg" in err and len(err) < 1000
    assert not out.exists()


def test_a_killed_runs_temporary_files_are_hidden_and_removed_by_the_next_run(tmp_path, capsys):
    import subprocess
    import sys

    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    dead_pid = int(gone.stdout)
    stale = tmp_path / f".c.ply.lmapd-{dead_pid}-abc123.part.ply"
    stale.write_bytes(b"x" * 1024)
    mine = tmp_path / f".c.ply.lmapd-{os.getpid()}-abc123.part.ply"  # a live process's: kept
    mine.write_bytes(b"x")
    other = tmp_path / ".keep.part"  # not ours: kept
    other.write_bytes(b"x")
    out = tmp_path / "c.ply"
    assert cli.main(["simulate", "--out", str(out), *SMALL]) == 0, capsys.readouterr().err
    assert not stale.exists() and mine.exists() and other.exists()
    assert _visible(tmp_path) == ["c.ply"]


def test_a_monte_carlo_gate_of_too_many_samples_is_refused_naming_the_keys(tmp_path, capsys):
    out = tmp_path / "c.ply"
    argv = ["simulate", "--set", "fidelity.noise_model=montecarlo", "--out", str(out)]
    assert cli.main([*argv, "--set", "fidelity.time_step_s=1e-11", *SMALL]) == 2
    err = _one_clear_line(capsys)
    assert "timing.range_gate_m" in err and "fidelity.time_step_s" in err and "65536" in err
    assert cli.main([*argv, "--set", "timing.range_gate_m=1e6", *SMALL]) == 2
    assert "timing.range_gate_m = 1e+06 m" in _one_clear_line(capsys)
    assert not out.exists()


def test_the_scene_checks_auto_time_step_is_the_echo_modules():
    import simcore
    from simcore import echo, scene

    for overrides in ({}, {"laser.pulse_width_s": 1e-10}, {"detector.bandwidth_hz": 1e9}):
        s = simcore.with_overrides(simcore.load_scene(), overrides)
        tau, b = s.laser.pulse_width_s, s.detector.bandwidth_hz
        assert scene.auto_time_step_s(s) == echo.default_time_step_s(tau, b)
