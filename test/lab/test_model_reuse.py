"""The lab's model contributions computed once per effect value: a fit holds its given effects at their values while
it varies a candidate, and later fits meet the same values again; each effect's per-block contributions are kept by
its class and values and by the modifier and response effects beside it (which change its conditions), so reuse
gives exactly what a fresh evaluation gives, and the kept memory stays within ``compare.PARTS_CACHE_BYTES``."""
from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest

from noise_monitor.bag.reader import open_bag
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.lab import compare
from noise_monitor.lab.analyze import baseline_effects
from noise_monitor.lab.compare import Comparison
from noise_monitor.lab.diagnose import EffectSpec, fit
from noise_monitor.lab.measure import Measurements, measure_frames
from noise_monitor.physics import Effect, NoiseModel, load_profile, make_effect
from noise_monitor.physics.effects.registry import effect_class

PROFILE = "ev76c661"


@pytest.fixture(scope="module")
def meas(tmp_path_factory: pytest.TempPathFactory) -> Measurements:
    """A 48-frame 160x128 lab bag (gains, exposures, temperatures) with a DSNU, whose size follows the temperature."""
    bag = simulate_bag(tmp_path_factory.mktemp("reuse") / "dsnu.mcap", PROFILE, "lab", effects=["dsnu=0.05"],
                       frames=48, width=160, height=128, seed=5)
    with open_bag(bag) as reader:
        return measure_frames(reader.frames(load_profile(PROFILE)))


def _comparison(meas: Measurements) -> Comparison:
    prof = load_profile(PROFILE)
    return Comparison(meas, NoiseModel(baseline_effects(prof, meas.segments[0].meta, meas.output_step_dn == 1.0)))


def _counting(monkeypatch: pytest.MonkeyPatch) -> Counter:
    """Counts the evaluations of each effect's contributions (by name and values)."""
    calls: Counter = Counter()
    evaluate = compare.Views._effect_parts

    def counted(self: compare.Views, e: Effect, *args: Any) -> Any:
        calls[(e.name, tuple(e.values.items()))] += 1
        return evaluate(self, e, *args)

    monkeypatch.setattr(compare.Views, "_effect_parts", counted)
    return calls


def test_a_fit_evaluates_the_effects_it_holds_once(meas: Measurements, monkeypatch: pytest.MonkeyPatch) -> None:
    comp = _comparison(meas)
    calls = _counting(monkeypatch)
    given = make_effect("dsnu", fraction=0.05)
    res = fit(comp, [EffectSpec.fit_all(effect_class("prnu"))], given=[given])
    prnu = [k for k in calls if k[0] == "prnu"]
    assert len(prnu) > 10  # the scan and the least squares tried many values
    assert calls[("dsnu", tuple(given.values.items()))] == 1  # before: once per value of the PRNU tried
    assert all(n == 1 for n in calls.values())  # the baseline's were computed when the comparison was made
    fresh = _comparison(meas)
    assert np.array_equal(fresh.residuals([given, *res.effects]), comp.residuals([given, *res.effects]))


def test_reuse_gives_what_a_fresh_evaluation_gives(meas: Measurements, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same DSNU beside a temperature offset (a modifier: a warmer sensor, more dark signal) and without it:
    kept apart; each read again from the kept contributions equals a fresh comparison's, bit for bit."""
    dsnu = make_effect("dsnu", fraction=0.05)
    warmer = make_effect("temperature_error", offset_c=8.0)
    sets = [[dsnu], [warmer, dsnu], [make_effect("temperature_error", offset_c=-8.0), dsnu]]
    comp = _comparison(meas)
    first = [comp.residuals(s) for s in sets]
    assert not np.array_equal(first[0], first[1])  # the modifier changed the DSNU's contribution
    calls = _counting(monkeypatch)
    again = [comp.residuals(s) for s in reversed(sets)][::-1]
    assert sum(calls.values()) == 0  # every contribution was kept
    for s, a, b in zip(sets, first, again):
        assert np.array_equal(a, b)
        assert np.array_equal(_comparison(meas).residuals(s), b)


def test_the_kept_contributions_stay_within_their_memory(meas: Measurements, monkeypatch: pytest.MonkeyPatch) -> None:
    assert compare.PARTS_CACHE_BYTES <= 128 * 2**20
    first = _comparison(meas).views._parts
    one = first.currsize / len(first)  # the baseline effects' contributions, about one entry each
    monkeypatch.setattr(compare, "PARTS_CACHE_BYTES", 3.5 * one)
    comp = _comparison(meas)
    kept = comp.views._parts
    calls = _counting(monkeypatch)
    values = [make_effect("prnu", sigma_pct=x) for x in (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)]
    readings = [comp.residuals([e]) for e in values]
    assert kept.currsize <= kept.maxsize
    assert np.array_equal(comp.residuals([values[0]]), readings[0])  # dropped, computed again, the same
    assert calls[("prnu", tuple(values[0].values.items()))] == 2
