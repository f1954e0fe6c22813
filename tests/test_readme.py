"""The README's first screen and its scene-key reference stay true."""

from pathlib import Path

import simcore

README = (Path(__file__).resolve().parent.parent / "README.md").read_text()


def test_the_first_screen_gives_the_two_commands():
    first_screen = "\n".join(README.splitlines()[:25])
    assert "make app" in first_screen and "make test" in first_screen


def test_every_scene_key_is_documented_in_the_readme_with_its_current_default():
    lines = README.splitlines()
    for row in simcore.key_reference():
        line = next((ln for ln in lines if ln.startswith(f"| `{row['key']}` |")), None)
        assert line is not None, f"{row['key']} missing from the README (run lmapd keys --markdown)"
        assert f"| {row['default']} |" in line, f"{row['key']}: README default is stale"


def test_the_readme_credits_nasa_for_the_mro_model():
    assert "NASA/JPL-Caltech" in README
