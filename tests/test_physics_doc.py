"""docs/physics.md: every citation of it resolves to an anchor, and every paper form has an entry.

Docstrings, the README and the other docs cite the model as ``docs/physics.md#eq-18`` (from
docs/ itself: ``physics.md#eq-18``). An anchor exists when a heading's GitHub slug is that name
(lowercase, spaces to '-', punctuation dropped, '-1', '-2' for repeats) or an explicit
``<a id="...">`` sets it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import simcore

ROOT = Path(__file__).resolve().parent.parent
PHYSICS = ROOT / "docs" / "physics.md"
CITATION = re.compile(r"(?<![\w.])physics\.md#([\w-]+)")
LOCAL_LINK = re.compile(r"\]\(#([\w-]+)\)")
EXPLICIT_ID = re.compile(r"<a\s+(?:id|name)=\"([^\"]+)\"")
FENCE = re.compile(r"^\s*(```|~~~)")


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: tags, links and code marks reduced to their text,
    lowercased, every character but letters, digits, '_', '-' and spaces dropped, spaces to '-'."""
    text = re.sub(r"<[^>]+>", "", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"[^\w\- ]", "", text.replace("`", "").strip().lower())
    return text.replace(" ", "-")


def anchors(markdown: str) -> set[str]:
    """Every anchor a Markdown page defines: heading slugs (with GitHub's -1, -2 for repeats)
    and explicit <a id="..."> / <a name="..."> targets."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    in_fence = False
    for line in markdown.splitlines():
        if FENCE.match(line):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if heading:
            slug = github_slug(heading.group(1))
            count = seen.get(slug, 0)
            seen[slug] = count + 1
            found.add(slug if count == 0 else f"{slug}-{count}")
    found.update(EXPLICIT_ID.findall(markdown))
    return found


def citing_files() -> list[Path]:
    files = [ROOT / "README.md"]
    for folder, pattern in (("simcore", "*.py"), ("app", "*.py"), ("docs", "*.md")):
        files += sorted((ROOT / folder).rglob(pattern))
    return [f for f in files if f.is_file()]


def citations() -> list[tuple[str, str]]:
    """(file relative to the repository, anchor) of every physics.md#anchor citation."""
    out = []
    for path in citing_files():
        text = path.read_text(encoding="utf-8")
        for anchor in CITATION.findall(text):
            out.append((str(path.relative_to(ROOT)), anchor))
    return out


@pytest.fixture(scope="module")
def physics_anchors() -> set[str]:
    return anchors(PHYSICS.read_text(encoding="utf-8"))


def test_the_physics_page_exists_and_the_readme_links_it():
    assert PHYSICS.is_file()
    assert "](docs/physics.md)" in (ROOT / "README.md").read_text(encoding="utf-8")


def test_github_slugs_follow_githubs_rules():
    assert github_slug("Eq. 18 — signal-to-noise ratio") == "eq-18--signal-to-noise-ratio"
    assert github_slug("`eq30_4pi` — Eq. 30: no 1/(4π)") == "eq30_4pi--eq-30-no-14π"
    assert github_slug('<a id="x"></a>The [pulse](#eq-1) table') == "the-pulse-table"
    assert anchors("## A\n## A\n```\n# not a heading\n```\n") == {"a", "a-1"}
    assert anchors('### <a id="eq-18"></a>Eq. 18 — SNR') == {"eq-18", "eq-18--snr"}


def test_every_citation_of_the_physics_page_names_an_anchor_it_defines(physics_anchors):
    missing = [(f, a) for f, a in citations() if a not in physics_anchors]
    assert not missing, f"docs/physics.md has no anchor for: {missing}"


def test_every_link_inside_the_physics_page_resolves(physics_anchors):
    links = LOCAL_LINK.findall(PHYSICS.read_text(encoding="utf-8"))
    assert links  # the page links its own sections
    assert sorted(set(links) - physics_anchors) == []


@pytest.mark.parametrize("number", range(1, 32))
def test_every_equation_of_the_paper_has_its_anchor(physics_anchors, number):
    assert f"eq-{number}" in physics_anchors


@pytest.mark.parametrize("form", simcore.PAPER_FORMS)
def test_every_paper_form_has_its_correction_entry(physics_anchors, form):
    assert f"paper-form-{form}" in physics_anchors


def test_every_test_the_physics_page_cites_exists_where_it_says():
    """The page cites its evidence as tests/FILE.py::test_name so that a reader can run it: when
    tests move, the citations must move with them."""
    text = PHYSICS.read_text(encoding="utf-8")
    cited = set(re.findall(r"(tests/[\w/]+\.py)::(test_\w+)", text))
    assert len(cited) > 50
    missing = [
        f"{path}::{name}"
        for path, name in sorted(cited)
        if not (ROOT / path).is_file()
        or not re.search(rf"^def {name}\(", (ROOT / path).read_text(encoding="utf-8"), re.M)
    ]
    assert not missing, f"docs/physics.md cites tests that are not there: {missing}"
