"""Test-session settings: an own ROS domain per test process, discovery on localhost, seeded RNG."""
from __future__ import annotations

import os
import tempfile

#: this process's pytest-xdist worker ("gw0", "gw1", ...), "" without xdist
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")


def _domain_id() -> int:
    """An own ROS domain (100..199) per test process; up to 100 pytest-xdist workers of one run never share one."""
    if not _WORKER:
        return 100 + os.getpid() % 100
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return 100 + (os.getppid() * count + int(_WORKER.removeprefix("gw"))) % 100


# Before rclpy is imported anywhere: isolate this process's DDS traffic.
os.environ["ROS_DOMAIN_ID"] = str(_domain_id())
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
# under pytest-xdist the workers share the cores: one thread each
os.environ.setdefault("OMP_NUM_THREADS", "1" if _WORKER else "2")
# exported estimator networks are cached per test session, not in the user's ~/.cache
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="noise_monitor_test_cache_")

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def rig_factory(request: pytest.FixtureRequest, estimator):
    """Make test rigs of the requesting module's ``Rig`` class (node + camera); closes them afterwards."""
    rigs = []

    def make(topic: str, **params):
        rigs.append(request.module.Rig(estimator, topic, **params))
        return rigs[-1]

    yield make
    for rig in rigs:
        rig.close()
