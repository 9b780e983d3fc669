"""In-memory frame sequences for the lab: a static tiled scene, a gain/exposure/temperature sweep, camera
motion between conditions, noise from ``NoiseModel.simulate(mode="joint")`` and 8-bit output."""
from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from ..monitor.frame import Frame
from ..physics import CameraProfile, NoiseModel

#: (gain dB, exposure s, temperature degC) per condition: gain, exposure and temperature sweeps.
DEFAULT_SWEEP: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.01, 25.0),
    (6.0, 0.01, 25.0),
    (12.0, 0.01, 25.0),
    (18.0, 0.01, 25.0),
    (6.0, 0.05, 25.0),
    (6.0, 0.2, 25.0),
    (6.0, 0.05, 45.0),
    (6.0, 0.05, 65.0),
)


def tiled_scene(height: int, width: int, seed: int = 0, tile: int = 32) -> np.ndarray:
    """A clean scene of flat tiles spanning 12..240 DN, a gentle global gradient and one textured tile."""
    rng = np.random.default_rng(seed)
    ny, nx = -(-height // tile), -(-width // tile)
    levels = rng.permutation(np.linspace(12.0, 240.0, ny * nx)).reshape(ny, nx)
    scene = np.kron(levels, np.ones((tile, tile)))[:height, :width]
    y, x = np.mgrid[0:height, 0:width]
    scene = scene + 3.0 * (x / width - 0.5) + 2.0 * (y / height - 0.5)
    ty, tx = min(tile, height), min(tile, width)
    scene[:ty, :tx] = 128.0 + 60.0 * np.sin(x[:ty, :tx] / 2.5) * np.cos(y[:ty, :tx] / 3.0)
    return np.clip(scene, 0.0, 255.0).astype(np.float32)


def simulate_frames(
    profile: CameraProfile,
    effects: Iterable[str] | dict = (),
    conditions: Sequence[tuple[float, float, float]] = DEFAULT_SWEEP,
    frames_per_condition: int = 6,
    width: int = 160,
    height: int = 128,
    seed: int = 0,
    frame_period_ns: int = 50_000_000,
    temperature_drift_c: float = 0.0,
) -> list[Frame]:
    """Frames of a camera (paper model + ``effects``) viewing a static scene; the camera moves between
    conditions (integer shifts) and is still within one, its sensor warming by ``temperature_drift_c`` (degC,
    evenly) over each condition's frames. Output rounded to 8 bit like a mono8 camera."""
    model = NoiseModel(extra=effects)
    rng = np.random.default_rng(seed)
    scene = tiled_scene(height, width, seed)
    frames: list[Frame] = []
    for c, (gain_db, exposure, temp) in enumerate(conditions):
        clean = np.roll(scene, (3 * c, 5 * c), axis=(0, 1))
        for j in range(frames_per_condition):
            warming = temperature_drift_c * j / max(frames_per_condition - 1, 1)
            meta = profile.metadata(gain_db=gain_db, exposure_time_s=exposure, sensor_temperature_c=temp + warming)
            noisy, _ = model.simulate(clean, meta, rng, mode="joint")
            i = len(frames)
            frames.append(Frame(i * frame_period_ns, np.rint(np.clip(noisy, 0, 255)).astype(np.float32), meta, index=i))
    return frames
