"""What the claims leave, for people, and the claimed values it names (bags: test_several_effects.py, `left_by_claims`
within the scatter on seed 630 and beyond it on seed 1102)."""
from __future__ import annotations

from typing import Any

from noise_monitor.lab.diagnose import Candidate, Diagnosis
from noise_monitor.lab.left import claims_at_limit, left_text
from noise_monitor.physics.effects import effect_class


def _candidate(effect: str, params: dict[str, float], rank: int, significant: bool,
               beyond: dict[str, Any] | None = None) -> Candidate:
    return Candidate(effect=effect, params=params, param_errors={}, chi2=0.0, explained_fraction=0.5, delta_bic=-10.0,
                     p_value=1e-9, significant=significant, reading="", rms_error_after_dn=0.0, rank=rank,
                     beyond=beyond, fitted=effect_class(effect)(**params))


def test_the_reading_names_what_to_try_only_where_the_claims_leave_more_than_the_scatter() -> None:
    left = {"claimed": ["dsnu"], "chi2": 3469.1, "dof": 609, "p_value": 0.0, "significant": True, "rms_error_dn": 2.4,
            "rms_error_by_component_dn": {"fixed": 0.209, "row": 0.0001, "outlier": 2.27},
            "refused_beyond": [{"effect": "hot_pixels", "p_value": 1.1e-11, "explained_fraction": 0.08,
                                "failed": ["explained fraction"]}], "at_limit": []}
    first, second = left_text(left, 2.99)
    assert first.startswith("left by the claims (dsnu): chi-square 3469.1 on 609 degrees of freedom (p < 1e-300)")
    assert "rms error 2.9900 -> 2.4000 DN (fixed 0.209, outlier 2.270)" in first
    assert "8.0% of what they leave" in second and second.endswith("try --add-effect hot_pixels=fit")
    within = {**left, "chi2": 590.0, "p_value": 0.7, "significant": False}
    assert len(left_text(within, 2.99)) == 1 and "within the measurement's scatter" in left_text(within, 2.99)[0]


def test_a_group_members_claimed_values_are_its_own_not_its_leads_refit() -> None:
    """A group claimed whole records its lead's refit on every member (``beyond``); a member's claimed values are its
    own fit alone (before 2026-12-01 they were the lead's: hot pixels claimed beside a DSNU read "fraction 0.297")."""
    refit = {"effect": "temperature_error", "given": ["dsnu"], "params": {"offset_c": 2.5}}
    member = _candidate("exposure_error", {"factor": 1.2}, 2, True, refit)
    lead = _candidate("temperature_error", {"offset_c": 1.9}, 2, True, refit)
    assert member.claimed_params == {"factor": 1.2} and lead.claimed_params == {"offset_c": 2.5}
    assert _candidate("prnu", {"sigma_pct": 1.2}, 3, False, refit).claimed_params is None


def test_a_claim_stretched_to_the_limit_of_its_range_is_named() -> None:
    """Seed 1057's claims: hot pixels at 20 % of the pixels (the limit of their fraction) standing for a DSNU, whose
    chi-square the measurement's scatter covers: the fraction is named as stretched; a dark multiplier at its limit
    that the data do not identify (any value in a range fits as well) is not, nor is a group member not in the model."""
    stretched = {"effect": "hot_pixels", "given": ["prnu"], "params": {"fraction": 0.2, "dark_multiplier": 1e7},
                 "param_ranges": {"dark_multiplier": [348.0, 1e7]}}
    ranked = [_candidate("prnu", {"sigma_pct": 1.04}, 1, True),
              _candidate("hot_pixels", {"fraction": 0.2, "dark_multiplier": 0.78}, 2, True, stretched),
              _candidate("dsnu", {"fraction": 10.0}, 2, True, stretched)]  # its group's alternative, at its own limit
    model = [effect_class("prnu")(sigma_pct=1.04), effect_class("hot_pixels")(**stretched["params"])]
    diag = Diagnosis(ranked, model, ranked[:2])
    assert claims_at_limit(diag) == [{"effect": "hot_pixels", "param": "fraction", "value": 0.2, "limit": 0.2}]
    left = {"claimed": ["prnu", "hot_pixels"], "chi2": 560.5, "dof": 474, "p_value": 0.0037, "significant": False,
            "rms_error_dn": 3.66, "rms_error_by_component_dn": {"outlier": 3.665}, "refused_beyond": [],
            "at_limit": claims_at_limit(diag)}
    first, second = left_text(left, 3.98)
    assert "within the measurement's scatter" in first
    assert second == ("  claimed at the upper limit of its allowed range: hot_pixels fraction = 0.2 (limit 0.2): the "
                      "data would take more, the effect may stand for another one; the claims are not a measurement of it")

