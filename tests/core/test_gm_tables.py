"""The Geiger-mode tables that depend on a few scalars (issue 41): computed once per scalar set,
kept in memory and on disk under a key that names the code that made them, and equal to what the
direct computation gives (the selection table and its medians bit for bit; the compiled Coates
sums within their rounding). Through the pipeline: a pitch change computes no table, a TNR
change re-runs only the detection's threshold half, and a first frame with the tables on disk
computes none and gives the same frame."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special, stats
from support.ci import skip_unless_ci

import simcore
from simcore.cache import TableCache
from simcore.echo.features import compiled_kernel
from simcore.pipeline import Pipeline
from simcore.receivers.gm_apd import coates as gm_coates
from simcore.receivers.gm_apd import selection as gm_selection
from simcore.receivers.gm_apd.windows import poisson_isf

S_S = 5e-9 / 2.446386  # Gamma(2, s) scale of the default 5 ns pulse [s]
BIN_S, JITTER_S = 250e-12, 200e-12
WIDTH, PRE, WINDOW = 6, 8, 115  # the default frame's peak window, lead and analysis window
GM = {"receiver.kind": "gm_apd", "pixels": 32, "gm.pulses": 100}


def direct_selection(n_pulses: int, coates: bool):
    """The selection table computed directly, as it was before its draws were cached: every
    count m's draws from the one seeded generator, their densest window by all pairwise bin
    differences, each count's Coates share from the counts before it and in its bin."""
    rng = np.random.default_rng(gm_selection.TABLE_SEED)
    top = min(gm_selection.TABLE_COUNTS, n_pulses)
    w_s = WIDTH * BIN_S / S_S
    lead_s = S_S * w_s / np.expm1(w_s)
    err, num, den = [], [], []
    for m in range(1, top + 1):
        r = gm_selection.TABLE_DRAWS if m <= gm_selection.SMALL_COUNTS else 2048
        phase = rng.random((r, 1)) * BIN_S
        t = phase + S_S * rng.standard_gamma(2.0, (r, m)) + JITTER_S * rng.standard_normal((r, m))
        b = np.sort(np.floor(t / BIN_S), axis=1)
        later = b[:, None, :] - b[:, :, None]
        first = np.argmax(((later >= 0) & (later < WIDTH)).sum(axis=2), axis=1)
        if coates:
            armed = n_pulses - (later > 0).sum(axis=1)
            same = (later == 0).sum(axis=1)
            a = np.maximum(armed, 1.0)
            share = np.where(armed > 0, -np.log1p(-np.minimum(same, a - 0.5) / a), 0.0) / same
        else:
            share = np.ones_like(b)
        e_bin = (b + 0.5) * BIN_S - 2.0 * S_S - phase
        ws = b[np.arange(r), first][:, None] - PRE
        w = np.where((b >= ws) & (b < ws + WINDOW), share, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            err.append((w * e_bin).sum(axis=1) / w.sum(axis=1))
        ws = np.floor((phase + lead_s) / BIN_S) - PRE
        w = np.where((b >= ws) & (b < ws + WINDOW), share, 0.0)
        num.append((w * e_bin).sum(axis=1).mean())
        den.append(w.sum(axis=1).mean())
    return err, np.array(num), np.array(den)


@pytest.mark.parametrize(("n_pulses", "coates"), [(10, True), (30, True), (30, False)])
def test_the_selection_table_from_cached_draws_is_the_direct_one_bit_for_bit(n_pulses, coates):
    table = gm_selection.selection_table(S_S, JITTER_S, BIN_S, WIDTH, PRE, WINDOW, n_pulses, coates)
    err, num, den = direct_selection(n_pulses, coates)
    assert table.err.shape[0] == len(err) == min(48, n_pulses)
    for m, e in enumerate(err):
        np.testing.assert_array_equal(table.err[m, : len(e)], e)
        assert np.isnan(table.err[m, len(e) :]).all()
    np.testing.assert_array_equal(table.num, num)
    np.testing.assert_array_equal(table.den, den)


def cumulative_sum_medians(table, n_pulses: int, k_t: float) -> np.ndarray:
    """The detected draws' weighted median at each node by the running sum over every sorted
    draw (the computation the bisection replaced)."""
    top = table.err.shape[0]
    m = np.arange(1, top + 1)
    p = np.clip(gm_selection.NODES / n_pulses, 0.0, 1.0)[:, None]
    w_m = special.bdtr(m, n_pulses, p) - special.bdtr(m - 1, n_pulses, p)
    w_m = w_m / w_m.sum(axis=1, keepdims=True)
    det = np.isfinite(table.err) & (table.peak >= k_t)
    flat_err = table.err[det]
    flat_m = np.broadcast_to(np.arange(top)[:, None], det.shape)[det]
    order = np.argsort(flat_err)
    flat_err, flat_m = flat_err[order], flat_m[order]
    cw = np.cumsum(w_m[:, flat_m] / table.draws[flat_m], axis=1)
    i = np.minimum((cw < 0.5 * cw[:, -1:]).sum(axis=1), len(flat_err) - 1)
    return flat_err[i]


@pytest.mark.parametrize("k_t", [1.0, 4.0])
def test_the_medians_by_bisection_are_the_running_sums_medians(k_t):
    table = gm_selection.selection_table(S_S, JITTER_S, BIN_S, WIDTH, PRE, WINDOW, 100, True)
    det = np.isfinite(table.err) & (table.peak >= k_t)
    top = table.err.shape[0]
    p = np.clip(gm_selection.NODES / 100, 0.0, 1.0)[:, None]
    m = np.arange(1, top + 1)
    w_m = special.bdtr(m, 100, p) - special.bdtr(m - 1, 100, p)
    w_m = w_m / w_m.sum(axis=1, keepdims=True)
    got = gm_selection._weighted_medians(table, det, w_m / table.draws[None, :])
    np.testing.assert_array_equal(got, cumulative_sum_medians(table, 100, k_t))


def test_a_cached_table_from_another_code_version_is_not_used(tmp_path, monkeypatch):
    monkeypatch.setenv("LMAPD_CACHE_DIR", str(tmp_path / "cache"))
    source = tmp_path / "table_code.py"
    source.write_text("VERSION = 1\n")
    made = []

    def compute():
        made.append(1)
        return {"values": np.arange(4.0) * len(made)}

    first = TableCache("demo", (source,))
    assert first.get((1.5, 3), compute)["values"][1] == 1.0
    again = TableCache("demo", (source,))  # a new process: nothing in memory
    assert again.get((1.5, 3), compute)["values"][1] == 1.0
    assert (again.computed, again.disk_hits, len(made)) == (0, 1, 1)
    source.write_text("VERSION = 2\n")  # another version of the code that makes the table
    changed = TableCache("demo", (source,))
    assert changed.get((1.5, 3), compute)["values"][1] == 2.0
    assert (changed.computed, changed.disk_hits, len(made)) == (1, 0, 2)
    # an entry whose stored key is another table's is not read either, even under this name
    other = TableCache("demo", (source,))
    entry = other.entry((7.0,))
    entry.parent.mkdir(parents=True, exist_ok=True)
    np.savez(entry, __key__=np.array("not this table"), values=np.zeros(4))
    with pytest.warns(UserWarning, match="another table's"):
        assert other.get((7.0,), compute)["values"][1] == 3.0
    assert other.computed == 1


def test_the_threshold_counts_take_scipy_stats_poisson_isf_steps_exactly():
    mu = np.geomspace(1e-8, 1e4, 2000)
    for q in (0.4, 1e-3, 1e-9, 1e-15, 1e-17, 1e-200):
        np.testing.assert_array_equal(poisson_isf(q, mu), stats.poisson.isf(q, mu))


def test_the_compiled_coates_sums_are_numpys_within_their_rounding():
    if compiled_kernel() is None:
        skip_unless_ci("numba unavailable: only the numpy sums run")
    rng = np.random.default_rng(7)
    alpha, h = rng.random(20_000) ** 3, rng.random(20_000) ** 4
    for n_pulses in (3, 100, 1000):
        mean_a = n_pulses * alpha
        live = (mean_a > 1e-12) & (h > 0)
        ref, got = np.zeros((4, len(h))), np.zeros((4, len(h)))
        gm_coates._summed_numpy(n_pulses, alpha, h, mean_a, live, ref)
        assert gm_coates._summed_compiled(n_pulses, alpha, h, mean_a, live, got)
        # at most 61 terms a sum, each rounded once: 61 x 2^-53 = 7e-15 of the sum of their
        # sizes; the moments are sums of positive terms, so of themselves (bound 1e-13); the
        # last is a sum of differences, bounded against the mean's own size
        np.testing.assert_allclose(got[:3], ref[:3], rtol=1e-13, atol=0.0)
        assert np.max(np.abs(got[3] - ref[3])) <= 1e-13 * np.max(np.abs(ref[0]))


def table_counts() -> dict[str, int]:
    """How many tables each of the Geiger-mode caches has computed so far in this process."""
    return {
        "draws": gm_selection.DRAWS.computed,
        "shifts": gm_selection.SHIFTS.computed,
        "selection": gm_selection.selection_table.cache_info().misses,
        "coates": gm_coates.TABLE.computed,
    }


def test_a_pitch_change_in_geiger_mode_recomputes_no_table():
    pipe = Pipeline()
    pipe.run(simcore.with_overrides(simcore.Scene(), GM))
    before, used = table_counts(), gm_selection.SHIFTS.memory_hits
    result = pipe.run(simcore.with_overrides(simcore.Scene(), {**GM, "pitch_deg": 4.0}))
    assert result.timings_s["detection"] > 0 and result.timings_s["receiver"] > 0  # re-ran
    assert gm_selection.SHIFTS.memory_hits > used  # the frame read its shifts...
    assert table_counts() == before  # ...and computed no table


def test_a_tnr_change_in_geiger_mode_re_runs_only_the_detection_and_the_cloud():
    pipe = Pipeline()
    scene = simcore.with_overrides(simcore.Scene(), GM)
    first = pipe.run(scene)
    changed = simcore.with_overrides(scene, {"tnr": 6.0})
    assert pipe.stages_to_run(changed) == ["detection", "cloud"]
    again = pipe.run(changed)
    fresh = Pipeline().run(changed)  # the cheap half from the kept prediction: the same frame
    np.testing.assert_array_equal(again.detection.range_sigma_m, fresh.detection.range_sigma_m)
    assert again.summary()["gm.range_sigma_m"] == fresh.summary()["gm.range_sigma_m"]
    assert not np.array_equal(first.detection.threshold_counts, again.detection.threshold_counts)


@pytest.mark.slow
def test_the_first_frame_with_the_tables_on_disk_computes_none_and_is_the_same_frame():
    scene = simcore.with_overrides(simcore.Scene(), {**GM, "gm.pulses": 73})
    made = Pipeline().run(scene)  # the tables of 73 pulses computed (or read) and stored
    gm_selection.DRAWS.clear_memory()
    gm_selection.SHIFTS.clear_memory()
    gm_selection.selection_table.cache_clear()
    gm_coates.TABLE.clear_memory()
    gm_coates._coates_table.cache_clear()
    before = table_counts()
    hits = gm_selection.DRAWS.disk_hits, gm_selection.SHIFTS.disk_hits, gm_coates.TABLE.disk_hits
    pipe = Pipeline()  # as the app's switch: a linear-mode frame, then the first Geiger-mode one
    pipe.run(simcore.with_overrides(simcore.Scene(), {"pixels": 32, "gm.pulses": 73}))
    first = pipe.run(scene)
    after = table_counts()
    assert after["draws"] == before["draws"] and after["shifts"] == before["shifts"]
    assert after["coates"] == before["coates"]
    assert gm_selection.DRAWS.disk_hits > hits[0] and gm_selection.SHIFTS.disk_hits > hits[1]
    assert gm_coates.TABLE.disk_hits > hits[2]
    assert first.summary()["gm.range_bias_m"] == made.summary()["gm.range_bias_m"]
    np.testing.assert_array_equal(first.detection.range_m, made.detection.range_m)
