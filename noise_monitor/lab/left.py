"""What the claimed explanations leave: the camera's model with every claimed effect at its claimed value against the
measurements (chi-square on the degrees of freedom net of every claimed parameter, its p-value, the net rms error in
total and per component), the candidates refitted beyond exactly those claims whose drop passed the F-test but
which another test refused, and the claimed values a fit pushed to the upper limit of their range (an effect
stretched to stand for another). Where the claims leave more than the measurement's scatter, the diagnosis is not complete:
those candidates are the ones to try next (``analyze --add-effect``)."""
from __future__ import annotations

from typing import Any

from scipy.stats import chi2 as chi2_dist

from .compare import Comparison, rms_error, rms_error_raw
from .diagnose import SIGNIFICANCE_P, Diagnosis, at_upper_limit, component_errors


def left_by_claims(comp: Comparison, diag: Diagnosis) -> dict[str, Any] | None:
    """What the claims leave (module docstring); None when nothing is claimed (then :func:`.signature.unexplained`
    reads the whole residual)."""
    if not diag.model:
        return None
    names = sorted(e.name for e in diag.model)
    r = comp.residuals(diag.model)
    chi2 = float(r @ r)
    dof = max(r.size - sum(len(c.params) for c in diag.claimed), 1)
    p = float(chi2_dist.sf(chi2, dof))
    rows = comp.cell_table(extra=diag.model)
    refused = [{"effect": c.effect, "p_value": b["p_value"], "explained_fraction": b["explained_fraction"],
                "failed": b["failed"]}
               for c in diag.candidates if not c.significant and (b := c.beyond) is not None
               and sorted(b["given"]) == names and b["p_value"] < SIGNIFICANCE_P]
    return {"claimed": [e.name for e in diag.model], "chi2": round(chi2, 3), "dof": dof, "p_value": p,
            "significant": p < SIGNIFICANCE_P, "rms_error_dn": rms_error(rows), "rms_error_raw_dn": rms_error_raw(rows),
            "rms_error_by_component_dn": {k: round(v, 5) for k, v in component_errors(rows).items()},
            "refused_beyond": refused, "at_limit": claims_at_limit(diag)}


def claims_at_limit(diag: Diagnosis) -> list[dict[str, Any]]:
    """The claimed model's values at the upper limit of their allowed range (an effect stretched, perhaps standing for
    another: hot pixels at 20 % of the pixels for a DSNU), but the parameters the claim's fit does not identify."""
    out = []
    for m, effect in zip(diag.claimed, diag.model, strict=True):
        ranges = m.beyond["param_ranges"] if m.beyond else (m.param_ranges or {})
        params = {k: effect.values[k] for k in m.params}
        out += [{"effect": m.effect, "param": name, "value": params[name], "limit": hi}
                for name, hi in at_upper_limit(type(effect), params, ranges)]
    return out


def left_text(left: dict[str, Any], rms_before_dn: float) -> list[str]:
    """:func:`left_by_claims` for people: one line, and where the claims leave more than the scatter, the candidates
    refused beyond them."""
    comps = ", ".join(f"{k} {v:.3f}" for k, v in left["rms_error_by_component_dn"].items() if v >= 0.0005)
    p = f"p = {left['p_value']:.2g}" if left["p_value"] > 0.0 else "p < 1e-300"
    verdict = ("more than the measurement's scatter: the claims do not explain all of it" if left["significant"] else
               "within the measurement's scatter")
    lines = [f"left by the claims ({', '.join(left['claimed'])}): chi-square {left['chi2']:.1f} on {left['dof']} "
             f"degrees of freedom ({p}), {verdict}; rms error {rms_before_dn:.4f} -> "
             f"{left['rms_error_dn']:.4f} DN" + (f" ({comps})" if comps else "")]
    lines += [f"  claimed at the upper limit of its allowed range: {a['effect']} {a['param']} = {a['value']:.4g} (limit "
              f"{a['limit']:g}): the data would take more, the effect may stand for another one; the claims are not a "
              f"measurement of it" for a in left["at_limit"]]
    if left["significant"]:
        lines += [f"  beyond them, significant by the F-test but refused: {c['effect']} (p = {c['p_value']:.2g}, "
                  f"{c['explained_fraction']:.1%} of what they leave; failed: {', '.join(c['failed'])}): try "
                  f"--add-effect {c['effect']}=fit" for c in left["refused_beyond"]]
    return lines
