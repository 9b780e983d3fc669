"""Run bags on a local pool of worker processes (no Ray needed): a hung bag is killed at its timeout,
a dead worker is reported with its exit reason and replaced, the other bags go on."""
from __future__ import annotations

import multiprocessing as mp
import signal
import time
from collections.abc import Iterable, Iterator
from multiprocessing.connection import Connection, wait
from typing import Any

from .task import MEMORY_EXIT_CODE, CampaignSettings, run_bag


def _ignore_sigint(signum: int, frame: Any) -> None:
    """Ctrl-C is the driver's: it stops the workers itself, so a worker never dies halfway through a write."""


def _worker_main(conn: Connection, settings: CampaignSettings) -> None:
    signal.signal(signal.SIGINT, _ignore_sigint)
    import noise_monitor.estimator  # noqa: F401  torch and the estimator code before the first bag's clock starts

    conn.send("ready")
    while True:
        try:
            path = conn.recv()
        except EOFError:
            return
        if path is None:
            return
        conn.send(run_bag(path, settings))


def death_reason(exitcode: int | None) -> str:
    """Why a worker process ended, in words."""
    if exitcode == MEMORY_EXIT_CODE:
        return "worker memory limit exceeded (worker stopped)"
    if exitcode is not None and exitcode < 0:
        name = signal.Signals(-exitcode).name
        hint = " (the kernel's out-of-memory killer sends it)" if name == "SIGKILL" else ""
        return f"worker process died: killed by {name}{hint}"
    return f"worker process died: exit code {exitcode}"


class _Worker:
    def __init__(self, ctx: Any, settings: CampaignSettings) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, settings), daemon=True)
        self.proc.start()
        child.close()
        self.ready = False
        self.path: str | None = None
        self.started = 0.0

    def send(self, path: str) -> None:
        self.path, self.started = path, time.monotonic()
        self.conn.send(path)

    def stop(self, kill: bool = False) -> None:
        if not kill and self.proc.is_alive():
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(2.0)
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join()
        self.conn.close()


class LocalPool:
    """``workers`` processes (spawned: nothing of the driver's state is inherited)."""

    name = "pool"

    def __init__(self, workers: int, timeout_s: float | None = None) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers, self.timeout_s = workers, timeout_s
        self.slots = workers

    def describe(self) -> dict[str, Any]:
        return {"backend": self.name, "workers": self.workers}

    def close(self) -> None:
        pass

    def run(self, paths: Iterable[str], settings: CampaignSettings) -> Iterator[dict[str, Any]]:
        """Outcomes of the bags as they finish (any order)."""
        ctx = mp.get_context("spawn")
        todo = iter(paths)
        pool = [_Worker(ctx, settings) for _ in range(self.workers)]
        more = True
        try:
            while True:
                for w in pool:
                    if w.ready and w.path is None and more:
                        nxt = next(todo, None)
                        if nxt is None:
                            more = False
                        else:
                            w.send(nxt)
                if not more and all(w.path is None for w in pool):
                    return
                ready = wait([w.conn for w in pool], timeout=0.1)
                now = time.monotonic()
                for i, w in enumerate(pool):
                    outcome, restart = None, False
                    if w.conn in ready:
                        try:
                            msg = w.conn.recv()
                        except (EOFError, OSError):
                            w.proc.join(5.0)
                            if w.path is None:
                                raise RuntimeError("a pool worker died at start-up: "
                                                   f"{death_reason(w.proc.exitcode)}") from None
                            outcome, restart = self._failed(w, death_reason(w.proc.exitcode)), True
                        else:
                            if msg == "ready":
                                w.ready = True
                                continue
                            outcome, restart = msg, bool(msg.get("restart_worker"))
                    elif w.path is not None and self.timeout_s and now - w.started > self.timeout_s:
                        outcome, restart = self._failed(w, f"timed out after {self.timeout_s:g} s (worker killed)"), True
                    if outcome is None:
                        continue
                    if restart:
                        w.stop(kill=True)
                        pool[i] = _Worker(ctx, settings)
                    else:
                        w.path = None
                    yield outcome
        finally:
            for w in pool:
                w.stop(kill=False)

    @staticmethod
    def _failed(w: _Worker, reason: str) -> dict[str, Any]:
        return {"path": w.path, "status": "failed", "reason": reason, "worker": f"pool pid {w.proc.pid}",
                "wall_s": round(time.monotonic() - w.started, 4)}
