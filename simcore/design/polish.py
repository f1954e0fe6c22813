"""After the screening: the cheapest feasible design polished along its cost variables (with
several objectives, the front's designs along each objective's), the front drawn, and designs of
it confirmed at the confirmation preset. Each evaluation goes through
:func:`simcore.design.search.evaluate_designs`, so it is a record like the screened ones."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

from .search import DERIVED_FROM, Record, evaluate_designs
from .study import Study, Variable

MAX_FRONT_POLISH = 6  # [-] front designs polished at most (spread along it), several objectives


def objective_variables(study: Study, name: str) -> list[Variable]:
    """The continuous variables the objective ``name`` grows with: the objective itself, a cost
    term, or what a derived cost figure is made of."""
    names = set(study.cost) if name == "cost" else {name}
    keys = {DERIVED_FROM.get(n, n) for n in names}
    return [v for v in study.variables if v.continuous and v.key in keys]


def polish_variables(study: Study) -> list[Variable]:
    """The continuous variables the (single) objective grows with (none with several: the front
    is polished instead, :func:`polish_front`)."""
    if len(study.minimize) != 1:
        return []
    return objective_variables(study, study.minimize[0])


def cheapest(records: Sequence[Record]) -> Record | None:
    """The feasible record of least first objective (None if none is feasible)."""
    ok = [r for r in records if r.feasible and r.objectives and math.isfinite(r.objectives[0])]
    return min(ok, key=lambda r: (r.objectives[0], r.number)) if ok else None


def polish(study: Study, best: Record, evaluator, state, out, cache, variables=None) -> Record:
    """Bisect each polish variable of the cheapest feasible design between its lower bound and
    its value (log scale where the variable has one), the other variables held, for
    ``polish_steps`` evaluations: feasibility is taken as monotone in a cost variable (more
    energy, a larger aperture never hurt), so the bisection closes on the least feasible value.
    ``variables``: those to bisect (default: :func:`polish_variables` of the one objective)."""
    current = best
    for v in polish_variables(study) if variables is None else variables:
        assert v.low is not None  # continuous: bounds
        lo, hi = v.low, float(current.params[v.key])
        if hi <= lo:
            continue
        low_design = {**current.params, v.key: lo}
        (rec,) = evaluate_designs(
            study, [low_design], study.preset, "polish", evaluator, state, out, cache
        )
        if rec.feasible:
            current = rec
            continue
        for _ in range(study.polish_steps):
            mid = math.sqrt(lo * hi) if v.log else 0.5 * (lo + hi)
            design = {**current.params, v.key: mid}
            (rec,) = evaluate_designs(
                study, [design], study.preset, "polish", evaluator, state, out, cache
            )
            if rec.feasible:
                hi, current = mid, rec
            else:
                lo = mid
    return current


def polish_front(study: Study, front: Sequence[Record], evaluator, state, out, cache) -> None:
    """With several objectives: bisect each front design (up to ``MAX_FRONT_POLISH``, spread
    along the front) along the continuous variables of each objective in turn, the others held,
    as :func:`polish` does for one objective. A screened design is only near the front; each of
    its polished twins lies on it (no feasible design of the same other variables costs less in
    that objective), so the front drawn from them is a front, not a scatter above it, with up to
    one point per objective for each design polished; a design bisected down to the lower bounds
    of one objective's variables is bisected along the others' too. At most ``polish_steps + 1``
    evaluations per design and objective polished."""
    if len(study.minimize) < 2 or study.polish_steps == 0 or not front:
        return
    n = min(len(front), MAX_FRONT_POLISH)
    picks = sorted({round(i * (len(front) - 1) / max(n - 1, 1)) for i in range(n)})
    along = [objective_variables(study, name) for name in study.minimize]
    for k, variables in enumerate(along):
        for i in picks if variables else ():
            rec = polish(study, front[i], evaluator, state, out, cache, variables)
            # bisected down to its bounds: the other costs bring it to the front
            if all(float(rec.params[v.key]) <= float(v.low or 0.0) for v in variables):
                for other in along[:k] + along[k + 1 :]:
                    rec = polish(study, rec, evaluator, state, out, cache, other)


def pareto_front(records: Sequence[Record]) -> list[Record]:
    """The feasible records no other feasible record beats in every objective."""
    ok = [r for r in records if r.feasible and all(math.isfinite(x) for x in r.objectives)]
    front = []
    for r in ok:
        dominated = any(
            all(a <= b for a, b in zip(o.objectives, r.objectives, strict=True))
            and any(a < b for a, b in zip(o.objectives, r.objectives, strict=True))
            for o in ok
        )
        if not dominated:
            front.append(r)
    unique: dict[str, Record] = {}
    for r in sorted(front, key=lambda r: (r.objectives, r.number)):
        unique.setdefault(json.dumps(r.params, sort_keys=True), r)
    return list(unique.values())


def to_confirm(study: Study, front: Sequence[Record]) -> list[Record]:
    """Up to ``study.confirm`` front designs, the cheapest first, spread along the front."""
    if not front or study.confirm == 0:
        return []
    if len(front) <= study.confirm:
        return list(front)
    picks = (
        [round(i * (len(front) - 1) / (study.confirm - 1)) for i in range(study.confirm)]
        if study.confirm > 1
        else [0]
    )
    return [front[i] for i in sorted(set(picks))]


def confirm(study: Study, chosen: Sequence[Record], evaluator, state, out, cache) -> list[Record]:
    designs = [r.params for r in chosen]
    return evaluate_designs(
        study,
        designs,
        study.confirm_preset,
        "confirm",
        evaluator,
        state,
        out,
        cache,
        of=[r.number for r in chosen],
    )
