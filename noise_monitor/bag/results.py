"""Replay results: the per-frame table, alarm episodes, per-source summaries and the CSV file."""
from __future__ import annotations

import csv
import re
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from noise_monitor.text import clip

#: Per-source summaries of the JSON contract (and a few more), from the per-frame numbers.
SUMMARY_KEYS = ("sigma_pn", "sigma_dcsn", "sigma_rn", "xi", "sigma_total", "sigma_model", "sigma_image",
                "xi_filtered", "sigma_temporal", "sigma_temporal_model")
#: Leading CSV columns; the numeric columns of processed frames follow in a fixed order.
BASE_COLUMNS = ("index", "stamp_ns", "time_s", "processed", "level", "alarm_state", "alarm", "skip_reason",
                "xi_measurement", "hold_event")
#: Stated operating conditions per frame (from the frame's metadata), CSV columns after the base ones.
CONDITION_KEYS = ("gain_db", "exposure_time_s", "sensor_temperature_c")
#: Numbers a processed frame has or not depending on the scene (a still camera, a patch the estimator can bound):
#: the CSV's last columns, always, in this order (empty where a frame has none), so that replays of different bags
#: with one estimator and model share their header
SCENE_DEPENDENT_KEYS = ("xi_bound", "xi_temporal", "sigma_temporal", "temporal_motion_px", "temporal_light_pct")


#: Rows per storage block of a :class:`FrameTable` column (blocks are never copied when the table grows).
BLOCK_ROWS = 4096


class _Column:
    """One column in fixed-size numpy blocks; rows never written hold ``fill``."""

    __slots__ = ("dtype", "fill", "blocks")

    def __init__(self, dtype: type, fill: Any) -> None:
        self.dtype, self.fill = dtype, fill
        self.blocks: list[np.ndarray] = []

    def set(self, row: int, value: Any) -> None:
        b, i = divmod(row, BLOCK_ROWS)
        while len(self.blocks) <= b:
            self.blocks.append(np.full(BLOCK_ROWS, self.fill, dtype=self.dtype))
        self.blocks[b][i] = value

    def values(self, n: int) -> np.ndarray:
        out = np.concatenate(self.blocks) if self.blocks else np.empty(0, dtype=self.dtype)
        if out.size < n:
            out = np.concatenate([out, np.full(n - out.size, self.fill, dtype=self.dtype)])
        return out[:n]


class FrameTable:
    """What a replay keeps of every frame, as columns: ~150 bytes per frame, whatever the length.

    Numbers (estimator, model, conditions) are float32 columns, NaN where a frame has none (skipped
    frames); texts (alarm state, cause, skip reason, which measurement drove xi, what restarted a still hold's
    measurement) are codes into a shared vocabulary.
    """

    _FIXED = (("index", np.int64, -1), ("stamp_ns", np.int64, 0), ("processed", np.bool_, False),
              ("level", np.int8, 0), ("alarm", np.bool_, False))
    #: The text columns (alarm state, cause, skip reason, which measurement drove xi, what restarted a hold's
    #: frame-difference measurement).
    TEXTS = ("alarm_state", "cause", "skip_reason", "xi_measurement", "hold_event")

    def __init__(self) -> None:
        self._n = 0
        self._fixed = {name: _Column(dtype, fill) for name, dtype, fill in self._FIXED}
        self._texts = {name: _Column(np.int32, -1) for name in self.TEXTS}
        self._vocab: list[str] = []
        self._codes: dict[str, int] = {}
        self._numbers: dict[str, _Column] = {}
        self._conditions: list[str] = []

    def __len__(self) -> int:
        return self._n

    def append(self, index: int, stamp_ns: int, processed: bool, level: int, alarm_active: bool, alarm_state: str,
               cause: str | None, skip_reason: str | None, numbers: Mapping[str, float],
               conditions: Mapping[str, float], xi_measurement: str | None = None,
               hold_event: str | None = None) -> None:
        i = self._n
        for name, value in (("index", index), ("stamp_ns", stamp_ns), ("processed", processed), ("level", level),
                            ("alarm", alarm_active)):
            self._fixed[name].set(i, value)
        for name, text in (("alarm_state", alarm_state), ("cause", cause), ("skip_reason", skip_reason),
                           ("xi_measurement", xi_measurement), ("hold_event", hold_event)):
            if text is not None:
                text = clip(text)  # reasons may echo bag contents (a 1 MB encoding string)
                self._texts[name].set(i, self._codes.setdefault(text, len(self._codes)))
                if len(self._vocab) < len(self._codes):
                    self._vocab.append(text)
        for key in conditions:
            if key not in self._conditions:
                self._conditions.append(key)
        for key, number in (*conditions.items(), *numbers.items()):
            col = self._numbers.get(key)
            if col is None:
                col = self._numbers[key] = _Column(np.float32, np.nan)
            col.set(i, number)
        self._n += 1

    def column(self, name: str) -> np.ndarray:
        """index, stamp_ns, processed, level, alarm, or time_s (seconds since the first frame)."""
        if name == "time_s":
            stamps = self._fixed["stamp_ns"].values(self._n)
            return (stamps - stamps[0]) / 1e9 if self._n else np.empty(0)
        return self._fixed[name].values(self._n)

    def texts(self, name: str) -> list[str | None]:
        """One of :attr:`TEXTS` for every frame (None where absent)."""
        return [self._vocab[c] if c >= 0 else None for c in self._texts[name].values(self._n)]

    def numbers(self, key: str) -> np.ndarray:
        """A number per frame (float64, NaN where the frame has none)."""
        col = self._numbers.get(key)
        return col.values(self._n).astype(np.float64) if col else np.full(self._n, np.nan)

    @property
    def number_keys(self) -> list[str]:
        """Numeric keys other than the conditions, in first-seen order."""
        return [k for k in self._numbers if k not in self._conditions]

    def temporal_model(self) -> np.ndarray:
        """The model's temporal noise on a still hold's measured blocks, ``sigma_temporal + xi_temporal`` (DN, NaN
        outside holds): the frame differences' measurement and this are what xi_temporal compares."""
        return self.numbers("sigma_temporal") + self.numbers("xi_temporal")

    def series(self, key: str) -> tuple[np.ndarray, np.ndarray]:
        """(time_s, value) of the frames that have ``key``."""
        v = self.numbers(key)
        ok = ~np.isnan(v)
        return self.column("time_s")[ok], v[ok]


def write_csv(table: FrameTable, path: Path) -> None:
    """One line per frame (skipped frames too, with their reason and empty numbers)."""
    numeric = [k for k in table.number_keys if k not in BASE_COLUMNS and k not in SCENE_DEPENDENT_KEYS]
    numeric += SCENE_DEPENDENT_KEYS
    base = {name: table.column(name) for name in ("index", "stamp_ns", "time_s", "processed", "level", "alarm")}
    texts = {name: table.texts(name) for name in ("alarm_state", "skip_reason", "xi_measurement", "hold_event")}
    values = {k: table.numbers(k) for k in (*CONDITION_KEYS, *numeric)}
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([*BASE_COLUMNS, *CONDITION_KEYS, *numeric])
        for i in range(len(table)):
            writer.writerow([int(base["index"][i]), int(base["stamp_ns"][i]), f"{base['time_s'][i]:.6f}",
                             int(base["processed"][i]), int(base["level"][i]), texts["alarm_state"][i],
                             int(base["alarm"][i]), texts["skip_reason"][i] or "", texts["xi_measurement"][i] or "",
                             texts["hold_event"][i] or "",
                             *("" if np.isnan(v[i]) else f"{v[i]:.6g}" for v in values.values())])


def alarm_episodes(table: FrameTable) -> list[dict[str, Any]]:
    """Contiguous runs of frames with an active alarm (processed or not): stamps, sign of xi, cause."""
    alarm = table.column("alarm").astype(np.int8)
    edges = np.diff(np.concatenate([[0], alarm, [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # [start, end)
    if not starts.size:
        return []
    index, stamps, t = table.column("index"), table.column("stamp_ns"), table.column("time_s")
    xi_f, causes = table.numbers("xi_filtered"), table.texts("cause")
    episodes = []
    for a, b in zip(starts, ends):
        xi = xi_f[a:b][~np.isnan(xi_f[a:b])]
        peak = float(xi[np.argmax(np.abs(xi))]) if xi.size else 0.0
        cause = Counter(c for c in causes[a:b] if c)
        episodes.append({
            "start_ns": int(stamps[a]), "end_ns": int(stamps[b - 1]),
            "start_s": round(float(t[a]), 6), "end_s": round(float(t[b - 1]), 6),
            "duration_s": round(float(t[b - 1] - t[a]), 6),
            "frames": int(b - a), "start_index": int(index[a]), "end_index": int(index[b - 1]),
            "sign": "-" if peak < 0 else "+", "peak_xi_dn": round(peak, 4),
            "mean_xi_dn": round(float(xi.mean()), 4) if xi.size else None,
            "cause": cause.most_common(1)[0][0] if cause else None,
            "active_at_end": bool(b == len(table)),
        })
    return episodes


def source_summaries(table: FrameTable) -> dict[str, dict[str, float | int | None]]:
    """mean, p5, p95 (and n) over the processed frames of each summary key, in DN."""
    out: dict[str, dict[str, float | int | None]] = {}
    processed = table.column("processed")
    for key in SUMMARY_KEYS:
        v = table.temporal_model() if key == "sigma_temporal_model" else table.numbers(key)
        v = v[processed & ~np.isnan(v)]
        if v.size:
            out[key] = {"mean": round(float(v.mean()), 4), "p5": round(float(np.percentile(v, 5)), 4),
                        "p95": round(float(np.percentile(v, 95)), 4), "n": int(v.size)}
        else:
            out[key] = {"mean": None, "p5": None, "p95": None, "n": 0}
    return out


def xi_measurements(table: FrameTable) -> dict[str, int]:
    """Processed frames by the measurement that drove their xi."""
    from noise_monitor.monitor.status import XI_MEASUREMENTS  # the monitor package: heavy, replays have it loaded

    counts = Counter(table.texts("xi_measurement"))
    return {kind: counts[kind] for kind in XI_MEASUREMENTS}


def skipped_frames(table: FrameTable) -> list[dict[str, Any]]:
    """index, stamp_ns and reason of every skipped frame."""
    skipped = np.flatnonzero(~table.column("processed"))
    index, stamps, reasons = table.column("index"), table.column("stamp_ns"), table.texts("skip_reason")
    return [{"index": int(index[i]), "stamp_ns": int(stamps[i]), "reason": reasons[i] or "unknown"} for i in skipped]


_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def skip_reasons(table: FrameTable) -> dict[str, int]:
    """Count of skipped frames per reason; reasons that differ only in their numbers (``metadata stale: 3.1 s``,
    ``3.2 s``, ...) are one, with N for the numbers that differ (the CSV keeps each frame's own)."""
    groups: dict[str, Counter[str]] = {}
    for s in skipped_frames(table):
        groups.setdefault(_NUMBER.sub("N", s["reason"]), Counter())[s["reason"]] += 1
    counts = Counter({_common(list(texts)): texts.total() for texts in groups.values()})
    return dict(counts.most_common())


def _common(texts: list[str]) -> str:
    """Texts alike but for their numbers, as one: the numbers they share kept, the others N."""
    numbers = [_NUMBER.findall(text) for text in texts]
    parts = _NUMBER.split(texts[0])
    out = [parts[0]]
    for i, part in enumerate(parts[1:]):
        values = {n[i] for n in numbers}
        out += [values.pop() if len(values) == 1 else "N", part]
    return "".join(out)


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
