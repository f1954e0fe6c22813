"""Design studies: the cheapest lidar that images a target well enough over a mission's envelope.

    study = simcore.design.load_study("assets/studies/mro_approach.toml")
    result = simcore.design.run(study, "out/", trials=50, workers=2)
    result.winner.params, result.front, result.table()

A study file (``simcore.design.study``) names the envelope (targets, distances, attitudes, Sun,
seeds), the design variables with their bounds, the requirements on summary figures (the
``quality.*`` imaging-quality figures, counts, range errors) aggregated over the envelope, and
the costs to minimise. ``run`` searches with optuna (``simcore.design.search``), evaluates each
design over the envelope with a Pipeline kept per envelope point (``simcore.design.evaluate``; a
variable re-runs only the stages it touches there), polishes the cheapest feasible design along
its cost variable, confirms the front at the reference preset, and writes what
``simcore.design.report`` describes into the output folder. A study that requires a pose
track's figures (``track.*``) has the trajectory's frames as its envelope points, each track
registered in time order (``design.study``'s docstring). The model: docs/design.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from .. import io
from ..sweep.table import _write_parquet
from .evaluate import Evaluator, StageTally, check_figures, flat_figures
from .polish import cheapest, confirm, pareto_front, polish, polish_front, to_confirm
from .report import (
    FRONT_NAME,
    REPORT_NAME,
    TRIALS_NAME,
    front_rows,
    report_text,
    trials_table,
    write_best,
    write_csv,
    write_figures,
)
from .search import Record, SearchState, _key, load_records, search
from .study import Requirement, Study, StudyError, Variable
from .study_file import load_study, study_from_dict

__all__ = [
    "DesignResult",
    "StudyFolder",
    "open_study",
    "Record",
    "Requirement",
    "Study",
    "StudyError",
    "Variable",
    "flat_figures",
    "load_study",
    "run",
    "study_from_dict",
]
STUDY_COPY = "study.toml"


@dataclass(frozen=True)
class DesignResult:
    """The outcome of :func:`run`.

    records : every design evaluated (screened, polished, confirmed), in the order run
    front : the feasible screened designs no other beats in every cost (one cost: the cheapest)
    winner : the cheapest design feasible at the confirmation preset (its confirmation record),
        else the cheapest feasible screened one; None if no design meets every requirement
    confirmed : the confirmation records
    tally : stages computed and reused over this run
    """

    study: Study
    out_dir: Path
    records: tuple[Record, ...]
    front: tuple[Record, ...]
    winner: Record | None
    confirmed: tuple[Record, ...]
    tally: StageTally
    n_run: int
    n_reused: int
    n_repeated: int
    wall_s: float

    def table(self):
        """Every record at every envelope point as a pyarrow Table (``trials.parquet``)."""
        return trials_table(self.study, self.records)

    def describe(self) -> str:
        n = sum(r.stage == "screen" for r in self.records)
        feasible = sum(r.stage == "screen" and r.feasible for r in self.records)
        if self.winner is None:
            head = "no design meets every requirement (see report.md)"
        else:
            cost = ", ".join(
                f"{k} = {v:.4g}"
                for k, v in zip(self.study.minimize, self.winner.objectives, strict=True)
            )
            head = f"winner: {cost}"
        taken = f", {self.n_reused} taken from {self.out_dir}" if self.n_reused else ""
        again = f", {self.n_repeated} proposed again (evaluated once)" if self.n_repeated else ""
        return (
            f"{n} designs screened ({feasible} feasible), {self.n_run} evaluated now{taken}"
            f"{again} -> {head}  [{self.wall_s:.1f} s]"
        )


def run(
    study: Study | str | Path,
    out_dir: str | Path,
    *,
    trials: int | None = None,
    workers: int | None = 0,
    scheduler: str | None = None,
    client=None,
    resume: bool = False,
    progress: bool = True,
) -> DesignResult:
    """Run a design study into ``out_dir`` (see the module docstring).

    Parameters
    ----------
    study : Study, or the path of a study file
    out_dir : the output folder (created): records/, trials.parquet, front.csv, best.toml,
        best/, front.png, margins.png, effects.png, report.md, study.toml
    trials : designs to screen (default: the study's ``trials``)
    workers : Dask worker processes on this machine (None: one per core; 0: this process)
    scheduler, client : an existing Dask scheduler's address or client instead
    resume : go on from the records in ``out_dir`` (a folder with records and no ``resume``
        is refused: nothing is overwritten)
    progress : a progress bar on stderr

    Raises StudyError before anything runs for an unknown figure, a folder that holds another
    study or a study's records without ``resume``.
    """
    from ..sweep.run import _Executor  # noqa: PLC0415  (Dask only when a study runs)

    start = time.perf_counter()
    if not isinstance(study, Study):
        study = load_study(study)
    n_trials = study.trials if trials is None else int(trials)
    if n_trials < 1:
        raise StudyError(f"--trials = {n_trials}: give at least 1")
    out = Path(out_dir)
    previous = _previous(study, out, resume)
    check_figures(study)
    out.mkdir(parents=True, exist_ok=True)
    io.write_json(out / "study.json", {"fingerprint": study.fingerprint, "source": study.source})
    if _is_toml(study.text):  # the study, for open_study and the app
        (out / STUDY_COPY).write_text(study.text)
    first = 1 + max((r.number for r in previous), default=-1)
    state = SearchState(next_number=first, first_number=first)
    cache = {_key(r.preset, r.params): r for r in previous if r.stage != "screen"}
    bar = tqdm(total=n_trials, desc=f"design {study.name}", unit="trial", disable=not progress)
    try:
        with _Executor(range(n_trials), workers, scheduler, client, 30.0) as submit:
            evaluator = Evaluator(
                getattr(submit, "client", None),
                quality=study.uses_quality,
                track=bool(study.tracks),
            )
            screened = search(study, n_trials, evaluator, state, out, cache, previous, bar.update)
            best = cheapest(screened)
            if best is not None:
                best = polish(study, best, evaluator, state, out, cache)
            candidates = [r for r in state.records if r.stage in ("screen", "polish")]
            front = _front(study, candidates)
            if len(study.minimize) > 1:  # the front's designs bisected onto it, then drawn again
                polish_front(study, front, evaluator, state, out, cache)
                candidates = [r for r in state.records if r.stage in ("screen", "polish")]
                front = _front(study, candidates)
            confirmed = confirm(study, to_confirm(study, front), evaluator, state, out, cache)
    finally:
        bar.close()
    winner = _winner(study, front, confirmed)
    result = DesignResult(
        study=study,
        out_dir=out,
        records=tuple(state.records),
        front=tuple(front),
        winner=winner,
        confirmed=tuple(confirmed),
        tally=state.tally,
        n_run=state.n_run,
        n_reused=state.n_reused,
        n_repeated=state.n_repeated,
        wall_s=time.perf_counter() - start,
    )
    _write_outputs(result)
    return result


@dataclass(frozen=True)
class StudyFolder:
    """A finished (or interrupted) study read back from its folder: the study, every record,
    the front, the confirmations and the winner, as :func:`run` chose them."""

    study: Study
    out_dir: Path
    records: tuple[Record, ...]
    front: tuple[Record, ...]
    confirmed: tuple[Record, ...]
    winner: Record | None
    skipped: tuple[str, ...] = ()  # the record files left out, each with why


def open_study(out_dir: str | Path) -> StudyFolder:
    """Read a study's output folder (its ``study.toml`` and ``records/``). Raises StudyError
    naming the folder if it holds no study; record files that are no record of this study
    (malformed, or with another count of requirements or costs) are left out and named in
    ``skipped``."""
    out = Path(out_dir)
    if not (out / STUDY_COPY).is_file():
        raise StudyError(f"{out} holds no study ({STUDY_COPY} is missing)")
    study = load_study(out / STUDY_COPY)
    skipped: list[str] = []
    records = []
    for r in load_records(out, skipped):
        shape = (len(r.margins), len(r.values), len(r.objectives), len(r.points))
        n_requirements, n_costs = len(study.requirements), len(study.minimize)
        if shape != (n_requirements, n_requirements, n_costs, len(study.envelope)):
            skipped.append(
                f"record {r.number}: {shape[0]} margins, {shape[2]} costs and {shape[3]} "
                f"envelope points, not this study's {n_requirements}, {n_costs} and "
                f"{len(study.envelope)}"
            )
        else:
            records.append(r)
    records.sort(key=lambda r: r.number)
    candidates = [r for r in records if r.stage in ("screen", "polish")]
    front = _front(study, candidates)
    confirmed = [r for r in records if r.stage == "confirm"]
    return StudyFolder(
        study=study,
        out_dir=out,
        records=tuple(records),
        front=tuple(front),
        confirmed=tuple(confirmed),
        winner=_winner(study, front, confirmed),
        skipped=tuple(skipped),
    )


def _is_toml(text: str) -> bool:
    import tomllib  # noqa: PLC0415

    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return False
    return bool(text)


def _previous(study: Study, out: Path, resume: bool) -> list[Record]:
    if out.exists() and not out.is_dir():
        raise StudyError(f"--out {out} is a file; give a folder")
    records = load_records(out) if out.is_dir() else []
    if records and not resume:
        raise StudyError(
            f"{out} holds {len(records)} evaluated designs of a study: --resume to go on with "
            "them, or give an empty folder"
        )
    marker = out / "study.json"
    if resume and marker.is_file():
        import json  # noqa: PLC0415

        known = json.loads(marker.read_text()).get("fingerprint")
        if known != study.fingerprint:
            raise StudyError(
                f"{out} holds another study (or this study file changed since): resume it with "
                "the same file, or give an empty folder"
            )
    return records


def _front(study: Study, candidates: list[Record]) -> list[Record]:
    if len(study.minimize) > 1:
        return pareto_front(candidates)
    ok = sorted((r for r in candidates if r.feasible), key=lambda r: (r.objectives[0], r.number))
    unique: dict[str, Record] = {}
    for r in ok:
        unique.setdefault(_key("", r.params), r)
    return list(unique.values())[: max(1, study.confirm)]


def _winner(study: Study, front: list[Record], confirmed: list[Record]) -> Record | None:
    ok = [c for c in confirmed if c.feasible]
    if ok:
        return min(ok, key=lambda r: (r.objectives[0], r.number))
    if study.confirm == 0 and front:
        return min(front, key=lambda r: (r.objectives[0], r.number))
    return None


def _write_outputs(result: DesignResult) -> None:
    study, out = result.study, result.out_dir
    _write_parquet(out / TRIALS_NAME, result.table())
    write_csv(out / FRONT_NAME, front_rows(study, result.front, result.confirmed))
    if result.winner is not None:
        write_best(study, result.winner, out)
    write_figures(study, result.records, result.front, result.winner, out)
    text = report_text(
        study,
        result.records,
        result.front,
        result.winner,
        result.confirmed,
        result.tally,
        result.wall_s,
    )
    with io.atomic_path(out / REPORT_NAME) as tmp:
        Path(tmp).write_text(text)
