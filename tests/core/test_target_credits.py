"""The shipped models' credits and terms (issue 29): each README quotes NASA's media usage
guidelines (not a paraphrase), names its source file, and the MRO carries JPL's credit line."""

from __future__ import annotations

import pytest

from simcore.target import TARGETS_DIR

SPACECRAFT = sorted(p.parent.name for p in TARGETS_DIR.glob("*/target.toml"))
QUOTED = (
    "generally are not subject to\n> copyright in the United States",
    "You may use this material for educational or informational\n> purposes",
    "NASA content used in a factual manner that does not imply endorsement",
    "NASA should be acknowledged as the source of the material.",
    "The use of\n> the Insignia, Logotype and NASA identifiers is protected by law",
    "https://www.nasa.gov/nasa-brand-center/images-and-media/",
)


def test_the_catalogue_has_the_six_spacecraft():
    assert SPACECRAFT == ["aqua", "kepler", "mro", "sentinel6", "tdrs", "tess"]


@pytest.mark.parametrize("name", SPACECRAFT)
def test_each_readme_quotes_the_guidelines_and_names_its_source_file(name):
    readme = (TARGETS_DIR / name / "README.md").read_text(encoding="utf-8")
    for passage in QUOTED:
        assert passage in readme, passage
    assert "Source file:" in readme
    assert "may be used freely" not in readme  # the old paraphrase


def test_the_mro_is_credited_as_jpl_asks_and_its_size_is_the_papers_setting():
    readme = (TARGETS_DIR / "mro" / "README.md").read_text(encoding="utf-8")
    assert "Courtesy NASA/JPL-Caltech" in readme
    assert "the paper's setting, not the spacecraft's size" in readme
    assert "13.6 m across its solar arrays" in readme


def test_the_tdrs_readme_says_its_model_is_not_to_scale():
    readme = (TARGETS_DIR / "tdrs" / "README.md").read_text(encoding="utf-8")
    assert "not to scale" in readme
    assert "19.6 m per unit" in readme
    assert "two 4.9 m single-access antennas" not in readme
