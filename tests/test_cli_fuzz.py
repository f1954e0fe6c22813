"""Hypothesis-generated scene files: `lmapd simulate` gives a result or one clear error line,
never a traceback, and never a half-written output."""

import dataclasses

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
