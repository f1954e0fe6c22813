"""The lessons as data (assets/lessons/NN-KEY.toml, read by app.logic.lessons.load_lessons): one
file per lesson in the order of their names, the card's paragraphs joined into one line each, and
a broken file refused with its name and the key at fault. Their figures are computed again from the
simulation by test_app_lessons.py."""

from __future__ import annotations

import shutil

import pytest

from app.logic.lessons import (
    BY_KEY,
    LESSONS,
    LESSONS_DIR,
    VIEWS,
    LessonError,
    lesson_from_record,
    load_lessons,
)


def test_each_lesson_is_one_file_named_after_its_key_in_the_order_of_the_names():
    names = sorted(p.name for p in LESSONS_DIR.glob("*.toml"))
    assert names == [f"{i:02d}-{lesson.key}.toml" for i, lesson in enumerate(LESSONS, 1)]
    assert len(BY_KEY) == len(LESSONS) >= 8


def test_a_cards_paragraphs_are_single_lines_without_doubled_spaces():
    for lesson in LESSONS:
        for text in (lesson.look, lesson.why, lesson.try_next, lesson.title):
            assert "\n" not in text and "  " not in text and text == text.strip(), lesson.key
        assert lesson.view in VIEWS and lesson.selection and lesson.figures
        assert all(isinstance(rc, tuple) and len(rc) == 2 for rc in lesson.selection)


def copy_of_lessons(tmp_path):
    folder = tmp_path / "lessons"
    shutil.copytree(LESSONS_DIR, folder)
    return folder


def test_a_copy_of_the_folder_loads_the_same_lessons(tmp_path):
    assert load_lessons(copy_of_lessons(tmp_path)) == LESSONS


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (lambda t: t.replace('key = "distance"', 'key = "distances"'), "not the file's name"),
        (lambda t: t.replace("reference = ", "referenc = "), "unknown key referenc"),
        (lambda t: t.replace("selection = [", "selection = 3 # ["), "03-distance.toml"),
        (lambda t: t.replace('view = "stats"', 'view = "sky"'), "view 'sky' is none of"),
        (lambda t: t.replace("[figures]", "[figures"), "03-distance.toml"),
        (lambda t: t.replace("\ntitle = ", "\n# title = "), "missing key title"),
        (lambda t: t.replace("\nd = 3000.0", '\nd = "far"'), "figure d is not a number"),
        (lambda t: t.replace("\nhit_scaled = 404", ""), "names the figure hit_scaled, not given"),
        (lambda t: t.replace("{snr_ref:.0f}", "{snr_ref:.0q}"), "its card cannot be written"),
    ],
)
def test_a_broken_lesson_file_is_refused_with_its_name(tmp_path, edit, said):
    folder = copy_of_lessons(tmp_path)
    path = folder / "03-distance.toml"
    path.write_text(edit(path.read_text(encoding="utf-8")), encoding="utf-8")
    with pytest.raises(LessonError, match="03-distance.toml") as refused:
        load_lessons(folder)
    assert said in str(refused.value)


def test_a_record_with_text_where_a_table_belongs_is_refused():
    record = {
        "key": "x",
        "title": "X",
        "settings": "pitch_deg=3",
        "selection": [[1, 2]],
        "look": "",
        "why": "",
        "try_next": "",
        "reference": "docs/physics.md",
        "reference_title": "",
    }
    with pytest.raises(LessonError, match="settings is not a table"):
        lesson_from_record(record, "x.toml")
