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


@pytest.fixture
def lamp_bag(tmp_path):
    """A photograph held still at 10 Hz, 192 x 128 px, whose light steps up by 30 % at frame 12 of 24 (a lamp switched
    on): an MCAP bag of image and metadata (ev76c661, 12 dB)."""
    import cv2
    from skimage import data

    from noise_monitor.bag.messages import image_msg, metadata_msg
    from noise_monitor.bag.writer import BagWriter
    from noise_monitor.physics import NoiseModel, load_profile

    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.02, sensor_temperature_c=35.0)
    clean = 20.0 + 0.6 * cv2.resize(data.camera(), (192, 128), interpolation=cv2.INTER_AREA).astype(np.float32)
    generator, model = np.random.default_rng(2), NoiseModel()
    bag = tmp_path / "lamp.mcap"
    with BagWriter(bag) as wr:
        for i in range(24):
            t = 1_000_000_000 + i * 100_000_000
            noisy, _ = model.simulate(clean * (1.3 if i >= 12 else 1.0), meta, generator, per_source=False)
            wr.write("/camera/metadata", metadata_msg(meta, t, "test"), t)
            wr.write("/camera/image_raw", image_msg(np.clip(np.rint(noisy), 0, 255).astype(np.uint8), t), t)
    return bag
