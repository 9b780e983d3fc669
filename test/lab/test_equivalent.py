"""Candidates the data cannot tell apart: with the dark current doubled, ``dark_current_law`` and
``exposure_error`` (both scale only the dark signal D x t) are one explanation at rank 1, reported as
alternatives with the observation that would separate them; effects the data do distinguish are never
grouped, nor are fits that found nothing."""
from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main
from noise_monitor.lab import analyze
from noise_monitor.lab.diagnose import EQUIVALENT_CHI2, Candidate, diagnosis_line, group_equivalent

torch.set_num_threads(1)
diagnose_module = importlib.import_module("noise_monitor.lab.diagnose")  # the package exports the function

PROFILE = "ev76c661"


def _bag(tmp: Path, name: str, effects: list[str]) -> Path:
    return simulate_bag(tmp / f"{name}.mcap", PROFILE, "lab", effects=effects, frames=48, width=160, height=128, seed=7)


@pytest.fixture(scope="module")
def dark_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _bag(tmp_path_factory.mktemp("equivalent"), "dark", ["dark_current_law=2"])


def test_dark_current_and_exposure_are_one_explanation(dark_bag: Path, tmp_path: Path) -> None:
    summary = analyze(dark_bag, PROFILE, estimator=None, report_dir=tmp_path / "report")
    cands = summary["candidates"]
    first = [c for c in cands if c["rank"] == 1]
    assert {c["effect"] for c in first} == {"dark_current_law", "exposure_error"}, \
        [(c["effect"], c["rank"], c["delta_bic"]) for c in cands[:4]]
    assert [c["effect"] for c in cands[:2]] == [c["effect"] for c in first]  # the group is listed together
    law, exposure = (next(c for c in first if c["effect"] == n) for n in ("dark_current_law", "exposure_error"))
    assert law["equivalent_to"] == ["exposure_error"] and exposure["equivalent_to"] == ["dark_current_law"]
    assert law["significant"] and exposure["significant"]
    assert law["params"]["scale"] == pytest.approx(2.0, rel=0.1)
    assert exposure["params"]["factor"] == pytest.approx(2.0, rel=0.1)
    assert cands[2]["rank"] == 2 and not cands[2]["equivalent_to"]
    assert [c["rank"] for c in cands] == sorted(c["rank"] for c in cands)
    text = law["indistinguishable"]
    assert text == exposure["indistinguishable"]
    assert text.startswith("the dark signal D x t is ")
    assert "cannot tell them apart" in text and "No noise measurement separates them" in text
    assert "measure the exposure time itself" in text
    assert summary["diagnosis"].startswith("most likely missing effect, one of 2 alternatives")
    html = (tmp_path / "report" / "report.html").read_text()
    assert "Candidates these data cannot tell apart" in html and "measure the exposure time itself" in html


def test_cli_names_the_alternatives(dark_bag: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["analyze", str(dark_bag), "--profile", PROFILE, "--quiet", "--no-estimator"]) == 0
    out = capsys.readouterr().out
    assert "(indistinguishable from exposure_error)" in out and "(indistinguishable from dark_current_law)" in out
    assert "one of 2 alternatives these data cannot tell apart" in out


def test_distinguishable_effect_stands_alone(tmp_path: Path) -> None:
    """Hidden gain error: the data tell it from extra read noise (and from every other candidate)."""
    summary = analyze(_bag(tmp_path, "gain", ["gain_error=1.3"]), PROFILE, estimator=None)
    best = summary["candidates"][0]
    assert best["effect"] == "gain_error" and best["rank"] == 1 and best["significant"]
    assert best["equivalent_to"] == [] and best["indistinguishable"] == ""
    assert summary["diagnosis"].startswith("most likely missing effect: ")
    read = next(c for c in summary["candidates"] if c["effect"] == "extra_read_noise")
    assert read["rank"] > 1 and "gain_error" not in read["equivalent_to"]


class _Fake:
    """A comparison whose residual vectors are set per effect name (baseline: ``base``)."""

    def __init__(self, base: np.ndarray, by_name: dict[str, np.ndarray]) -> None:
        self.base, self.by_name = base, by_name

    def residuals(self, extra: Any = ()) -> np.ndarray:
        return self.by_name[extra[0].name] if extra else self.base


class _Effect:
    def __init__(self, name: str) -> None:
        self.name = name


def _cand(name: str, chi2: float, delta_bic: float, significant: bool) -> Candidate:
    return Candidate(effect=name, params={"p": 1.0}, param_errors={"p": 0.1}, chi2=chi2, explained_fraction=0.5,
                     delta_bic=delta_bic, p_value=0.0, significant=significant, reading=name,
                     rms_error_after_dn=0.0, fitted=_Effect(name))  # type: ignore[arg-type]


def test_grouping_rule(monkeypatch: pytest.MonkeyPatch) -> None:
    """Members within EQUIVALENT_CHI2 of the best are grouped and share its rank and claim; a candidate as
    far off as the threshold is not; weak fits near "no effect" whose changes differ are not, though they
    lie within EQUIVALENT_CHI2 of each other; fits indistinguishable from no effect are never grouped."""
    monkeypatch.setattr(diagnose_module, "explain", lambda comp, members, chi2, z: "alternatives")
    rng = np.random.default_rng(0)
    base = rng.normal(size=400) + 3.0  # the model without any candidate: chi2 ~ 4000
    fit = rng.normal(size=400)  # a candidate that explains the residual
    step = np.zeros(400)
    step[:16] = 0.45  # chi2 distance 3.24, at most 0.45 standard errors
    far = np.zeros(400)
    far[:40] = 0.35  # chi2 distance 4.9 (> EQUIVALENT_CHI2) though every entry is within 0.35
    weak = np.zeros(400)
    weak[100:110] = -1.0  # a weak fit: chi2 change 10
    other = np.zeros(400)
    other[200:203] = -1.0  # another weak fit, chi2 3 from the first: its change is not the same
    comp = _Fake(base, {"a": fit, "b": fit + step, "c": fit + far, "w1": base + weak, "w2": base + weak + other,
                        "n1": base + 0.01, "n2": base + 0.011})
    cands = [_cand("a", fit @ fit, 3000.0, True), _cand("c", 500.0, 2990.0, True), _cand("b", 510.0, 2980.0, False),
             _cand("w1", 3990.0, 2.0, False), _cand("w2", 3990.0, 1.0, False),
             _cand("n1", 3990.0, -5.0, False), _cand("n2", 3990.0, -5.1, False)]
    assert far @ far > EQUIVALENT_CHI2 >= step @ step and other @ other < EQUIVALENT_CHI2
    out = group_equivalent(comp, cands)  # type: ignore[arg-type]
    assert [(c.effect, c.rank) for c in out] == [("a", 1), ("b", 1), ("c", 2), ("w1", 3), ("w2", 4), ("n1", 5),
                                                 ("n2", 6)]
    a, b, c, w1, w2, n1, n2 = out
    assert a.equivalent_to == ["b"] and b.equivalent_to == ["a"] and not c.equivalent_to
    assert b.significant and a.indistinguishable == b.indistinguishable == "alternatives" and not c.indistinguishable
    assert not w1.equivalent_to and not w2.equivalent_to
    assert not n1.equivalent_to and not n2.equivalent_to  # both found nothing: not an explanation
    line = diagnosis_line([x.as_dict() for x in out])  # c, claimed too (as if beyond a), is named after the group
    assert line == ("most likely missing effect, one of 2 alternatives these data cannot tell apart: alternatives; "
                    "beyond it, also missing: c")
