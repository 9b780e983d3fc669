"""Replay results: per-frame rows, alarm episodes, per-source summaries and the CSV file."""
from __future__ import annotations

import csv
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: Per-source summaries of the JSON contract (and a few more), from the per-frame numbers.
SUMMARY_KEYS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "xi", "sigma_total", "sigma_model", "sigma_image",
                "xi_filtered")
#: Leading CSV columns; the numeric columns of processed frames follow in a fixed order.
BASE_COLUMNS = ("index", "stamp_ns", "time_s", "processed", "level", "alarm_state", "alarm", "skip_reason")
#: Stated operating conditions per frame (from the frame's metadata), CSV columns after the base ones.
CONDITION_KEYS = ("gain_db", "exposure_time_s", "sensor_temperature_c")


class CompactNumbers(Mapping):
    """A read-only name -> float mapping stored as float32 values with a shared key tuple.

    A replay keeps one per frame: ~25 numbers cost ~130 bytes instead of ~2 KB as a dict, so a
    20,000-frame replay stays within a few MB.
    """

    __slots__ = ("_keys", "_values")
    _interned: dict[tuple[str, ...], tuple[str, ...]] = {}

    def __init__(self, values: Mapping[str, float]) -> None:
        keys = tuple(values)
        self._keys = self._interned.setdefault(keys, keys)
        self._values = np.fromiter(values.values(), dtype=np.float32, count=len(keys))

    def __getitem__(self, key: str) -> float:
        try:
            return float(self._values[self._keys.index(key)])
        except ValueError:
            raise KeyError(key) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)


@dataclass(slots=True)
class FrameRow:
    """What the replay keeps of one frame (compact: numbers as float32)."""

    index: int
    stamp_ns: int
    time_s: float
    processed: bool
    level: int
    alarm_state: str
    alarm_active: bool
    cause: str | None
    skip_reason: str | None
    numbers: Mapping[str, float] = field(default_factory=dict)
    conditions: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.numbers = CompactNumbers(self.numbers)
        self.conditions = CompactNumbers(self.conditions)

    def csv_row(self) -> dict[str, Any]:
        return {"index": self.index, "stamp_ns": self.stamp_ns, "time_s": f"{self.time_s:.6f}",
                "processed": int(self.processed), "level": self.level, "alarm_state": self.alarm_state,
                "alarm": int(self.alarm_active), "skip_reason": self.skip_reason or "",
                **{k: f"{v:.6g}" for k, v in self.conditions.items()},
                **{k: f"{v:.6g}" for k, v in self.numbers.items()}}


def write_csv(rows: list[FrameRow], path: Path) -> None:
    """One line per frame (skipped frames too, with their reason and empty numbers)."""
    numeric: list[str] = []
    for r in rows:
        numeric += [k for k in r.numbers if k not in numeric and k not in BASE_COLUMNS]
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=[*BASE_COLUMNS, *CONDITION_KEYS, *numeric], restval="")
        writer.writeheader()
        for r in rows:
            writer.writerow(r.csv_row())


def alarm_episodes(rows: list[FrameRow]) -> list[dict[str, Any]]:
    """Contiguous runs of frames with an active alarm (processed or not): stamps, sign of xi, cause."""
    episodes: list[dict[str, Any]] = []
    current: list[FrameRow] = []
    for r in [*rows, None]:
        if r is not None and r.alarm_active:
            current.append(r)
            continue
        if current:
            episodes.append(_episode(current, still_active=r is None))
            current = []
    return episodes


def _episode(run: list[FrameRow], still_active: bool) -> dict[str, Any]:
    xi = [r.numbers["xi_filtered"] for r in run if "xi_filtered" in r.numbers]
    peak = max(xi, key=abs) if xi else 0.0
    causes = Counter(r.cause for r in run if r.cause)
    return {
        "start_ns": run[0].stamp_ns, "end_ns": run[-1].stamp_ns,
        "start_s": round(run[0].time_s, 6), "end_s": round(run[-1].time_s, 6),
        "duration_s": round(run[-1].time_s - run[0].time_s, 6),
        "frames": len(run), "start_index": run[0].index, "end_index": run[-1].index,
        "sign": "-" if peak < 0 else "+", "peak_xi_dn": round(float(peak), 4),
        "mean_xi_dn": round(float(np.mean(xi)), 4) if xi else None,
        "cause": causes.most_common(1)[0][0] if causes else None,
        "active_at_end": still_active,
    }


def source_summaries(rows: list[FrameRow]) -> dict[str, dict[str, float | int | None]]:
    """mean, p5, p95 (and n) over the processed frames of each summary key, in DN."""
    out: dict[str, dict[str, float | int | None]] = {}
    for key in SUMMARY_KEYS:
        v = np.array([r.numbers[key] for r in rows if r.processed and key in r.numbers], dtype=float)
        if v.size:
            out[key] = {"mean": round(float(v.mean()), 4), "p5": round(float(np.percentile(v, 5)), 4),
                        "p95": round(float(np.percentile(v, 95)), 4), "n": int(v.size)}
        else:
            out[key] = {"mean": None, "p5": None, "p95": None, "n": 0}
    return out


def skip_reasons(rows: list[FrameRow]) -> dict[str, int]:
    """Count of skipped frames per reason."""
    return dict(Counter(r.skip_reason or "unknown" for r in rows if not r.processed).most_common())


def truth_check(alarms: list[dict[str, Any]], truth_episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Alarm episodes vs the corruption episodes of a simulated bag's truth sidecar.

    A corruption counts as detected by an alarm of the same xi sign that starts inside it; the delay is
    alarm start - corruption start. Alarms starting outside every corruption are false alarms.
    """
    found = []
    used: set[int] = set()
    for ep in truth_episodes:
        hit = next((i for i, a in enumerate(alarms) if ep["start_ns"] <= a["start_ns"] <= ep["end_ns"]
                    and a["sign"] == ep["xi_sign"]), None)
        if hit is not None:
            used.add(hit)
        delay = round((alarms[hit]["start_ns"] - ep["start_ns"]) / 1e9, 3) if hit is not None else None
        found.append({"corrupted": ep["corrupted"], "start_ns": ep["start_ns"], "end_ns": ep["end_ns"],
                      "xi_sign": ep["xi_sign"], "detected": hit is not None, "delay_s": delay})
    false = [a for i, a in enumerate(alarms)
             if i not in used and not any(ep["start_ns"] <= a["start_ns"] <= ep["end_ns"] for ep in truth_episodes)]
    detected = sum(f["detected"] for f in found)
    return {"episodes": found, "detected": detected, "missed": len(found) - detected, "false_alarms": len(false)}
