"""Run bags as Ray tasks: a local Ray started for the campaign, or an existing cluster (``--ray ADDRESS``).

One task per bag (``num_cpus=1``, no retries: a failure is reported, not repeated); at most one task per
CPU of the cluster in flight, so the driver holds O(CPUs) object refs whatever the campaign's size and a
task's timeout runs from its submission. A task past its timeout is cancelled with its worker killed.
"""
from __future__ import annotations

import socket
import time
from collections.abc import Iterable, Iterator
from typing import Any

from .task import CampaignSettings, run_bag


class RayUnavailable(RuntimeError):
    """Ray is not installed, or the cluster cannot be reached."""


def _check_reachable(address: str, timeout_s: float = 3.0) -> None:
    """A TCP connection to ``host:port`` (``ray://host:port`` too) before Ray waits on it for a minute."""
    if address == "auto":
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise RayUnavailable(f"Ray address {address!r} is not HOST:PORT, ray://HOST:PORT or auto")
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise RayUnavailable(f"Ray cluster at {address} is unreachable: {exc.strerror or exc}") from None


class RayPool:
    """Ray tasks; ``address`` None starts a local Ray with ``workers`` CPUs (stopped again by close())."""

    name = "ray"

    def __init__(self, address: str | None, workers: int, timeout_s: float | None = None) -> None:
        try:
            import ray
        except ImportError:
            raise RayUnavailable("Ray is not installed (pip install 'noise_monitor[fleet]')") from None
        self.ray, self.address, self.workers, self.timeout_s = ray, address, workers, timeout_s
        if address is not None:
            _check_reachable(address)
        try:
            if address is None:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                         configure_logging=False, _node_ip_address="127.0.0.1")
            else:
                ray.init(address=address, log_to_driver=False, configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise RayUnavailable(f"cannot start or join Ray at {address or 'local'}: "
                                 f"{' '.join(str(exc).split())}") from None
        self.slots = max(1, int(ray.cluster_resources().get("CPU", workers)))

    def describe(self) -> dict[str, Any]:
        return {"backend": self.name, "address": self.address or "local", "cluster_cpus": self.slots}

    def close(self) -> None:
        self.ray.shutdown()

    def _reason(self, exc: Exception) -> str:
        ex = self.ray.exceptions
        if isinstance(exc, ex.OutOfMemoryError):
            return "worker out of memory (killed by Ray's memory monitor)"
        if isinstance(exc, ex.WorkerCrashedError):
            return "worker process died (crashed or killed) while replaying the bag"
        if isinstance(exc, ex.TaskCancelledError):
            return "task cancelled"
        lines = [ln for ln in str(exc).splitlines() if ln.strip()]
        return f"{type(exc).__name__}: {lines[-1] if lines else ''}"

    def run(self, paths: Iterable[str], settings: CampaignSettings) -> Iterator[dict[str, Any]]:
        ray = self.ray
        task = ray.remote(run_bag).options(num_cpus=1, max_retries=0)
        settings_ref = ray.put(settings)
        todo = iter(paths)
        inflight: dict[Any, tuple[str, float]] = {}
        cancelled: set[Any] = set()
        more = True
        try:
            while True:
                while more and len(inflight) < self.slots:
                    nxt = next(todo, None)
                    if nxt is None:
                        more = False
                    else:
                        inflight[task.remote(nxt, settings_ref)] = (nxt, time.monotonic())
                if not inflight:
                    return
                refs = list(inflight)
                ready, rest = ray.wait(refs, num_returns=1, timeout=0.1)  # returns at the first finished task
                if ready and rest:
                    ready += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
                for ref in ready:
                    path, t0 = inflight.pop(ref)
                    if ref in cancelled:
                        cancelled.discard(ref)
                        continue
                    try:
                        out = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        out = {"path": path, "status": "failed", "reason": self._reason(exc), "worker": "ray",
                               "wall_s": round(time.monotonic() - t0, 4)}
                    out["task_s"] = round(time.monotonic() - t0, 4)  # submit -> result, scheduling included
                    yield out
                now = time.monotonic()
                for ref, (path, t0) in list(inflight.items()):
                    if self.timeout_s and ref not in cancelled and now - t0 > self.timeout_s:
                        ray.cancel(ref, force=True)
                        cancelled.add(ref)
                        yield {"path": path, "status": "failed", "worker": "ray", "wall_s": round(now - t0, 4),
                               "reason": f"timed out after {self.timeout_s:g} s (task cancelled, worker killed)"}
        finally:
            for ref in inflight:
                if ref not in cancelled:
                    ray.cancel(ref, force=True)
