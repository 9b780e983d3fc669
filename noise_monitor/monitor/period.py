"""The periodic ``/diagnostics`` status: one summary of the frames of each period (node and replay).

A :class:`PeriodSummary` collects the frame results of one period (:meth:`~PeriodSummary.add`) and turns
them into one :class:`StatusReport` (:meth:`~PeriodSummary.report`), then starts the next period. The
level is the worst of the period's frames, so an alarm raised inside the period shows even if it cleared
before the period ended; without frames the monitor's idle report applies (the last status, STALE after
``image_timeout_s``). Values (numeric strings): the contract's latest filtered ``sigma_pn``,
``sigma_dcsn``, ``sigma_rn``, ``sigma_total``, ``xi`` (= ``xi_filtered``) with ``sigma_model`` and
``sigma_image``; the period's frame counts, skip reasons and per-frame xi mean/min/max; the alarm state;
the monitor's cumulative counters. Thread-safe: the node adds from its worker and reports from a timer.
"""
from __future__ import annotations

import re
import threading
from collections import Counter

import numpy as np

from .pipeline import FrameResult, Monitor
from .status import StatusReport

#: Contract values taken from the latest evaluated frame's filtered estimates (``FrameResult.filtered``).
FILTERED_KEYS = ("pn", "dcsn", "rn", "total")
#: Counters reported as of the period's last frame (the others, e.g. frames_dropped, as of the report).
FRAME_COUNTERS = ("frames_received", "frames_processed", "frames_skipped")
_NUMBER = re.compile(r"\d+(?:\.\d+)?")


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def skip_category(reason: str) -> str:
    """A skip reason without its particulars: the text before the first ':' with numbers as N
    (``metadata missing``, ``N usable patches (need N)``, ``image NxN is smaller than the patch size N``)."""
    return _NUMBER.sub("N", reason.split(":", 1)[0].strip())[:80] or "unknown"


class PeriodSummary:
    """Frame results of the current period and the status summarising them (see the module docstring)."""

    def __init__(self, start_ns: int) -> None:
        self._lock = threading.Lock()
        self._latest_processed: FrameResult | None = None  # across periods: the contract's latest values
        self._counters: dict[str, int] | None = None  # monitor counters at the start of the period
        self._frame_counters = dict.fromkeys(FRAME_COUNTERS, 0)  # the latest added result's counters
        self._start(start_ns)

    def restart(self, start_ns: int) -> None:
        """Begin the period again at ``start_ns`` (the clock jumped), keeping its frames."""
        with self._lock:
            self.start_ns = start_ns

    def _start(self, start_ns: int) -> None:
        self.start_ns = start_ns
        self._results: list[FrameResult] = []

    def add(self, result: FrameResult) -> None:
        """A frame result of this period (evaluated or skipped)."""
        with self._lock:
            self._results.append(result)
            self._frame_counters = {k: result.counters[k] for k in FRAME_COUNTERS if k in result.counters}
            if result.processed:
                self._latest_processed = result

    @property
    def frames(self) -> int:
        """Frame results collected in the current period."""
        with self._lock:
            return len(self._results)

    def report(self, monitor: Monitor, now_ns: int) -> StatusReport:
        """The status of the period ending at ``now_ns`` (stamp it with ``now_ns``); a new period begins."""
        with self._lock:
            results, start = self._results, self.start_ns
            latest = self._latest_processed
            self._start(now_ns)
            # frames counted as the added results count them: a frame being evaluated right now belongs to
            # the next period in its counters too (frames_received of the period's last frame)
            counters = {**monitor.counters, **self._frame_counters}
            before, self._counters = self._counters or {k: 0 for k in counters}, counters
        state = monitor.alarm.state
        values: dict[str, str] = {}
        if latest is not None:
            values.update({f"sigma_{k}": _fmt(latest.filtered[k]) for k in FILTERED_KEYS})
            assert latest.xi_filtered is not None  # evaluated frames carry it
            values["xi"] = values["xi_filtered"] = _fmt(latest.xi_filtered)
            values["sigma_model"] = _fmt(latest.model["total"])
            values["sigma_image"] = _fmt(latest.sigma["image"])
        xi = np.array([r.xi for r in results if r.processed and r.xi is not None], dtype=np.float64)
        skips = Counter(skip_category(r.skip_reason or "unknown") for r in results if not r.processed)
        values.update({
            "period_s": _fmt((now_ns - start) / 1e9),
            "period_frames": str(len(results)),
            "period_processed": str(len(results) - sum(skips.values())),
            "period_skipped": str(sum(skips.values())),
            "period_dropped": str(counters["frames_dropped"] - before.get("frames_dropped", 0)),
            "period_lost": str(counters["frames_lost"] - before.get("frames_lost", 0)),
            "period_alarm_frames": str(sum(r.alarm_active for r in results)),
        })
        if xi.size:
            values.update(xi_mean=_fmt(float(xi.mean())), xi_min=_fmt(float(xi.min())), xi_max=_fmt(float(xi.max())))
        values.update({f"skipped: {reason}": str(n) for reason, n in skips.most_common()})
        if results and not results[-1].processed and results[-1].skip_reason:
            values["last_skip_reason"] = results[-1].skip_reason
        values.update({
            "alarm": "1" if state.active else "0",
            "alarm_state": state.name,
            "alarm_raised": "1" if state.active or any(r.alarm_active for r in results) else "0",
            "alarm_episodes": str(state.episodes),
            **{k: str(v) for k, v in counters.items()},
        })
        if not results:  # no frame in this period: the last status, or STALE after image_timeout_s
            idle = monitor.idle_report(now_ns)
            extra = {k: v for k, v in idle.values.items() if k == "image_age_s"}
            return StatusReport(idle.level, monitor.name, idle.message, monitor.hardware_id, {**values, **extra})
        worst = max(reversed(results), key=lambda r: r.level)  # the latest one of the worst level
        message = worst.message
        if results[-1].level < worst.level:
            message = f"{message}; latest: {results[-1].message}"
        return StatusReport(worst.level, monitor.name, message, monitor.hardware_id, values)
