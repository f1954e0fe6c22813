"""The Design page, a child of the app's logic: the finished design studies in the app's
``--studies`` folder (each a folder ``lmapd design`` wrote), one drawn at a time (its costs and
front, its front designs with their requirement margins), and any of its designs opened in the
main views at the envelope point where it meets its requirements least (its scene and seed).

A page names a study only by its folder's name, which must be one of those listed: nothing
outside the studies folder is read (a folder, or a file in it, that links outside is not listed).
Record files that are no record of the study are left out and named in the message."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import simcore
from app.payloads import design as payload
from simcore import design

STATE_KEYS = ("design_study",)  # what a page sets: a listed study's name
MAX_STUDIES = 200  # folders listed at most
MAX_NAMED = 5  # malformed records named in the message at most (the rest counted)


def _inside(folder: Path, root: Path) -> bool:
    """Whether ``folder``, its ``records/`` and every file in them resolve inside ``root``
    (no link out of the studies folder)."""
    try:
        paths = [folder, *folder.iterdir()]
        records = folder / "records"
        if records.is_dir():
            paths += list(records.iterdir())
        return all(p.resolve().is_relative_to(root) for p in paths)
    except (OSError, RuntimeError):  # unreadable, or a loop of links
        return False


class DesignStudies:
    """``design_studies`` (the names), ``design_front`` (figure), ``design_rows`` and
    ``design_message`` on a trame state, from ``design_study``; ``open_design(number)`` hands the
    design's scene to ``open_scene(scene, label)``."""

    def __init__(
        self,
        state,
        studies_dir: str | Path | None,
        open_scene: Callable[[simcore.Scene, str], None],
    ):
        self.state = state
        self.folder = Path(studies_dir) if studies_dir else None
        self.open_scene = open_scene
        self.current: design.StudyFolder | None = None
        state.update(
            {
                "design_studies": self.names(),
                "design_study": None,
                "design_front": None,
                "design_rows": [],
                "design_message": "",
            }
        )
        state.change(*STATE_KEYS)(self.select)

    def refresh(self) -> None:
        """List the study folders again (a session forked from the app built at launch: the
        studies written since)."""
        self.state.design_studies = self.names()

    def names(self) -> list[str]:
        """The study folders (those holding a study.toml), by name: only folders that are
        inside the studies folder once links are resolved, and whose files are too."""
        if self.folder is None or not self.folder.is_dir():
            return []
        root = self.folder.resolve()
        found = sorted(
            p.name
            for p in self.folder.iterdir()
            if p.is_dir() and (p / "study.toml").is_file() and _inside(p, root)
        )
        return found[:MAX_STUDIES]

    def select(self, **_: Any) -> None:
        """Draw the study the page chose (re-listing the folder: a study may have finished)."""
        name = self.state.design_study
        names = self.names()
        update: dict[str, Any] = {"design_studies": names, "design_front": None, "design_rows": []}
        self.current = None
        if not name:
            update["design_message"] = ""
        elif not isinstance(name, str) or name not in names:
            update["design_message"] = "Choose a study from the list."
        else:
            try:
                self.current = design.open_study(self.folder / name)
            except (simcore.SceneError, OSError, ValueError) as exc:
                update["design_message"] = f"Cannot read the study {name}: {exc}"
            else:
                study = self.current.study
                skipped = self.current.skipped
                screened = sum(r.stage == "screen" for r in self.current.records)
                winner = "no design meets every requirement"
                if self.current.winner is not None:
                    winner = "the winner is listed first"
                update |= {
                    "design_front": payload.front_figure(self.current),
                    "design_rows": payload.design_rows(self.current),
                    "design_message": f"{study.name}: {screened} designs screened over "
                    f"{len(study.envelope)} envelope points; {winner}."
                    + (f" Left out {len(skipped)} malformed records: " if skipped else "")
                    + "; ".join(skipped[:MAX_NAMED])
                    + (
                        f"; and {len(skipped) - MAX_NAMED} more" if len(skipped) > MAX_NAMED else ""
                    ),
                }
        with self.state:
            self.state.update(update)

    def open_design(self, number: Any = None, *_: Any, **__: Any) -> None:
        """Open design ``number`` of the drawn study at its least favourable envelope point."""
        folder = self.current
        row = next((r for r in self.state.design_rows if r.get("number") == number), None)
        rec = (
            None
            if folder is None
            else next((r for r in folder.records if r.number == number), None)
        )
        if row is None or rec is None:
            with self.state:
                self.state.design_message = "Choose a design of the study drawn above."
            return
        try:
            scene = folder.study.scene(rec.params, row["point"], rec.preset)
        except simcore.SceneError as exc:
            with self.state:
                self.state.design_message = f"Design {number} cannot be opened: {exc}"
            return
        self.open_scene(scene, f"design {number} of {folder.study.name}, point {row['point']}")
