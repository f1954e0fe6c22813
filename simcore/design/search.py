"""The search: optuna proposes designs (seeded; TPE with constraints for one objective, NSGA-II
for several), each evaluated over the envelope at the screening preset (``evaluate_designs``);
what follows, the polish and the confirmation, is ``simcore.design.polish``.

Every evaluated design is a record written to ``DIR/records/`` as soon as it is finished, so an
interrupted study keeps every finished trial; ``resume`` replays them into a new optuna study
(and reuses any polish or confirmation already done) and goes on to the number of trials asked.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import io
from ..scene import SceneError
from .evaluate import Evaluator, PointOutcome, StageTally
from .study import Study, Variable

RECORDS_DIR = "records"
STAGES = ("screen", "polish", "confirm")
DERIVED_FROM = {  # the scene key a derived cost figure grows with
    "receive.aperture_area_m2": "receive.aperture_diameter_m",
    "detector.pixel_count": "detector.pixels",
    "laser.pulse_energy_total_j": "laser.pulse_energy_j",
}


@dataclass
class Record:
    """One design evaluated over the envelope at one preset.

    number : its order in the study; stage : "screen", "polish" or "confirm"; of : the screened
    record a confirmation confirms (-1 otherwise); points : per envelope point, its figures or
    {"error": text}; values : each requirement's aggregate over the envelope; margins : how far
    each is met (negative: fails); objectives : the costs, in ``minimize`` order.
    """

    number: int
    stage: str
    preset: str
    params: dict[str, Any]
    points: list[dict[str, Any]]
    values: list[float]
    margins: list[float]
    objectives: list[float]
    feasible: bool
    error: str | None = None
    frame_s: float = 0.0
    of: int = -1

    @property
    def violation(self) -> float:
        """The sum of the shortfalls, each relative to its bound (0: feasible)."""
        return sum(max(0.0, -m) for m in self.margins)

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Record:
        """A record from its file's JSON, the numbers ``io.write_json`` wrote as null (NaN) or
        "inf" (a lost frame's error) read back as floats."""
        fields = {k: data[k] for k in cls.__dataclass_fields__ if k in data}
        for key in _NUMBER_LISTS:
            fields[key] = [_number(v) for v in fields[key]]
        fields["points"] = [
            {k: v if k == "error" else _number(v) for k, v in p.items()} for p in fields["points"]
        ]
        return cls(**fields)


_NON_FINITE = {"inf": math.inf, "-inf": -math.inf}


def _number(value: Any) -> Any:
    """A JSON number back as ``io.write_json`` wrote it: null is NaN, "inf" and "-inf" are
    infinities; anything else as it is."""
    if value is None:
        return math.nan
    return _NON_FINITE.get(value, value) if isinstance(value, str) else value


def _is_number(value: Any) -> bool:
    number = _number(value)
    return isinstance(number, int | float) and not isinstance(number, bool)


@dataclass
class SearchState:
    """What the search has done: every record, and the stage tally of this run."""

    records: list[Record] = field(default_factory=list)
    tally: StageTally = field(default_factory=StageTally)
    n_run: int = 0
    n_reused: int = 0  # designs whose record a previous run left in the folder
    n_repeated: int = 0  # designs this run had evaluated already (the search proposed them again)
    next_number: int = 0  # records are numbered in the order they were run, across resumes
    first_number: int = 0  # this run's first record number (those below: a previous run's)


def _key(preset: str, params: Mapping[str, Any]) -> str:
    return preset + " " + json.dumps(params, sort_keys=True)


_NUMBER_LISTS = ("values", "margins", "objectives")


def record_problem(data: Any) -> str | None:
    """Why ``data`` (a record file's JSON) is not a record's shape, or None."""
    if not isinstance(data, dict):
        return f"not an object but {type(data).__name__}"
    missing = [
        k for k in ("number", "stage", "preset", "params", "points", "feasible") if k not in data
    ]
    missing += [k for k in _NUMBER_LISTS if k not in data]
    if missing:
        return f"no {', '.join(missing)}"
    checks = {
        "number": isinstance(data["number"], int) and not isinstance(data["number"], bool),
        "stage": data["stage"] in STAGES,
        "preset": isinstance(data["preset"], str),
        "params": isinstance(data["params"], dict),
        "points": isinstance(data["points"], list)
        and all(isinstance(p, dict) for p in data["points"]),
        "feasible": isinstance(data["feasible"], bool),
        **{
            key: isinstance(data[key], list) and all(_is_number(v) for v in data[key])
            for key in _NUMBER_LISTS
        },
    }
    wrong = [key for key, ok in checks.items() if not ok]
    return f"{', '.join(wrong)} of the wrong kind" if wrong else None


def load_records(out: Path, skipped: list[str] | None = None) -> list[Record]:
    """The records of a study folder; a file that is no record (a record cut short by a kill:
    its design runs again) is left out, and named with why in ``skipped`` if given."""
    folder = out / RECORDS_DIR
    if not folder.is_dir():
        return []
    records = []
    for path in sorted(folder.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            problem: str | None = f"not JSON ({type(exc).__name__})"
        else:
            problem = record_problem(data)
        if problem is None:
            records.append(Record.from_json(data))
        elif skipped is not None:
            skipped.append(f"{path.name}: {problem}")
    return records


def _write(out: Path, rec: Record) -> None:
    (out / RECORDS_DIR).mkdir(parents=True, exist_ok=True)
    io.write_json(out / RECORDS_DIR / f"{rec.stage}_{rec.number:05d}.json", rec.to_json())


def evaluate_designs(
    study: Study,
    designs: Sequence[Mapping[str, Any]],
    preset: str,
    stage: str,
    evaluator: Evaluator,
    state: SearchState,
    out: Path,
    cache: dict[str, Record],
    of: Sequence[int] | None = None,
) -> list[Record]:
    """Each design over the whole envelope at ``preset``; records written as each finishes
    (those already in ``cache``, from a previous run, are taken as they are)."""
    done: dict[int, Record] = {}
    jobs, scenes_ok = [], {}
    for i, params in enumerate(designs):
        hit = cache.get(_key(preset, params))
        if hit is not None:
            done[i] = hit
            if hit.number < state.first_number:
                state.n_reused += 1
            else:
                state.n_repeated += 1
            continue
        scenes, error = [], None
        for p in range(len(study.envelope)):
            try:
                scenes.append(study.scene(params, p, preset))
            except SceneError as exc:
                error = f"SceneError: {exc}"
                break
        if error is not None:
            done[i] = _record(study, -1, stage, preset, params, [], error)
            continue
        scenes_ok[i] = scenes
        jobs += [(i, scene, p) for p, scene in enumerate(scenes)]
    outcomes: dict[int, dict[int, PointOutcome]] = {i: {} for i in scenes_ok}
    for i, point, outcome in evaluator.evaluate(jobs):
        state.tally.add(outcome)
        outcomes[i][point] = outcome
    if study.tracks:  # each track's frames registered in time order, once all are in
        for i in scenes_ok:
            outcomes[i] = evaluator.track(study, designs[i], preset, outcomes[i])
    for i in scenes_ok:
        points = [outcomes[i][p] for p in range(len(study.envelope))]
        done[i] = _record(study, 0, stage, preset, designs[i], points, None)
    records = []
    for i in range(len(designs)):
        rec = done[i]
        if _key(preset, rec.params) not in cache:
            rec.number = state.next_number
            state.next_number += 1
            rec.of = of[i] if of is not None else -1
            state.records.append(rec)
            state.n_run += 1
            cache[_key(preset, rec.params)] = rec
            _write(out, rec)
        elif rec not in state.records:
            state.records.append(rec)
        records.append(rec)
    return records


def _record(study, number, stage, preset, params, points: Sequence[PointOutcome], error):
    figures: list[dict[str, Any]] = []
    for o in points:
        if o.error is not None:
            error = error or o.error
            figures.append({"error": o.error})
        else:
            figures.append(dict(o.figures or {}))
    values, margins = [], []
    for req in study.requirements:
        per_point = [f.get(req.figure, math.nan) if "error" not in f else math.nan for f in figures]
        value = req.aggregate(per_point) if figures else math.nan
        values.append(value)
        margins.append(req.margin(value))
    try:
        objectives = study.objective_values(study.scene(params, 0, preset))
    except SceneError:
        objectives = [math.nan] * len(study.minimize)
    feasible = error is None and all(m >= 0 for m in margins)
    return Record(
        number=number,
        stage=stage,
        preset=preset,
        params=dict(params),
        points=figures,
        values=values,
        margins=margins,
        objectives=objectives,
        feasible=feasible,
        error=error,
        frame_s=float(sum(o.frame_s for o in points if math.isfinite(o.frame_s))),
    )


# ----------------------------------------------------------------------------------------------
# optuna
# ----------------------------------------------------------------------------------------------
def _distribution(v: Variable):
    from optuna import distributions as d  # noqa: PLC0415  (only when a study runs)

    if v.choices:
        return d.CategoricalDistribution(list(v.choices))
    assert v.low is not None and v.high is not None  # a variable has bounds or choices
    if v.integer:
        return d.IntDistribution(int(v.low), int(v.high), log=v.log)
    return d.FloatDistribution(v.low, v.high, log=v.log)


def _violations(study: Study, rec: Record) -> list[float]:
    if rec.error is not None:
        return [1e12] * max(1, len(study.requirements))
    return [r.violation(v) for r, v in zip(study.requirements, rec.values, strict=True)] or [0.0]


def make_optuna_study(study: Study, n_trials: int):
    """An in-memory optuna study with the study's seeded, constraint-aware sampler."""
    import optuna  # noqa: PLC0415

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # the samplers read each trial's constraints (Trial.set_constraint: feasible when <= 0)
    sampler: optuna.samplers.BaseSampler
    if len(study.minimize) > 1:
        sampler = optuna.samplers.NSGAIISampler(
            population_size=max(10, min(50, n_trials // 4)), seed=study.seed
        )
    else:
        sampler = optuna.samplers.TPESampler(
            seed=study.seed, n_startup_trials=max(5, min(20, n_trials // 5))
        )
    return optuna.create_study(directions=["minimize"] * len(study.minimize), sampler=sampler)


def _replay(ostudy, study: Study, records: Sequence[Record], dists) -> None:
    import optuna  # noqa: PLC0415

    for rec in records:
        ok = rec.error is None and all(math.isfinite(v) for v in rec.objectives)
        violations = _violations(study, rec)
        ostudy.add_trial(
            optuna.trial.create_trial(
                state=optuna.trial.TrialState.COMPLETE if ok else optuna.trial.TrialState.FAIL,
                values=rec.objectives if ok else None,
                params=rec.params,
                distributions=dists,
                constraints={f"c{i}": v for i, v in enumerate(violations)},
            )
        )


def search(
    study: Study,
    n_trials: int,
    evaluator: Evaluator,
    state: SearchState,
    out: Path,
    cache: dict[str, Record],
    previous: Sequence[Record],
    progress: Callable[[int], None] | None = None,
) -> list[Record]:
    """Screen designs until ``n_trials`` screened records exist (``previous`` ones included)."""
    import optuna  # noqa: PLC0415

    dists = {v.key: _distribution(v) for v in study.variables}
    ostudy = make_optuna_study(study, n_trials)
    queue = [r for r in previous if r.stage == "screen"][:n_trials]  # to replay, in order
    state.records.extend(queue)
    for r in queue:
        cache[_key(r.preset, r.params)] = r
    if progress:
        progress(len(queue))

    def tell(trial, rec: Record) -> None:
        ok = rec.error is None and all(math.isfinite(v) for v in rec.objectives)
        for i, v in enumerate(_violations(study, rec)):
            trial.set_constraint(f"c{i}", v)
        if ok:
            ostudy.tell(trial, rec.objectives)
        else:
            ostudy.tell(trial, state=optuna.trial.TrialState.FAIL)

    screened: list[Record] = []
    per_batch = max(1, math.ceil(2 * max(evaluator.n_workers, 1) / len(study.envelope)))
    while len(screened) < n_trials:
        batch = [ostudy.ask(dists) for _ in range(min(per_batch, n_trials - len(screened)))]
        # a resumed study: the seeded sampler proposes again what it proposed before the
        # interrupt, and is told the recorded outcome, so the study goes on as if never stopped
        recs: list[Record | None] = [None] * len(batch)
        for j, trial in enumerate(batch):
            if queue and trial.params == queue[0].params:
                recs[j] = queue.pop(0)
        if queue and None in recs:  # the proposals differ (other workers, another optuna)
            for trial, rec in zip(batch, recs, strict=True):
                if rec is None:
                    ostudy.tell(trial, state=optuna.trial.TrialState.FAIL)
                else:
                    tell(trial, rec)
            screened += [r for r in recs if r is not None]
            _replay(ostudy, study, queue, dists)  # the rest as they are
            screened += queue
            queue = []
            continue
        new = [j for j, r in enumerate(recs) if r is None]
        if new:  # a design screened before (a repeat proposal) is not run again
            designs = [dict(batch[j].params) for j in new]
            done = evaluate_designs(
                study, designs, study.preset, "screen", evaluator, state, out, cache
            )
            for j, rec in zip(new, done, strict=True):
                recs[j] = rec
            if progress:
                progress(len(new))
        for trial, rec in zip(batch, recs, strict=True):
            assert rec is not None
            tell(trial, rec)
        screened += [r for r in recs if r is not None]
    return screened
