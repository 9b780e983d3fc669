"""Clean synthetic scenes for simulated bags: a world of flat, textured and gradient tiles at many
intensities, seen through a camera window that stays put or pans (integer-pixel moves, no blur)."""
from __future__ import annotations

import cv2
import numpy as np

#: World size relative to the camera view (the camera pans over the extra area).
WORLD_SCALE = (1.6, 1.8)  # (rows, columns)
TILE_KINDS = ("flat", "texture", "gradient")


def make_world(rng: np.random.Generator, height: int, width: int, tiles_across: int = 6) -> np.ndarray:
    """A float32 scene in DN larger than the view: a grid of tiles, each flat, textured or a gradient.

    Tile levels are spread over 8..247 DN so every frame holds dark, mid-grey and bright regions.
    """
    if height < 16 or width < 16:
        raise ValueError(f"image size must be at least 16x16 pixels, got {width}x{height}")
    wh, ww = int(round(height * WORLD_SCALE[0])), int(round(width * WORLD_SCALE[1]))
    tile = max(8, ww // tiles_across)
    rows, cols = -(-wh // tile), -(-ww // tile)
    n = rows * cols
    levels = rng.permutation(np.linspace(8.0, 247.0, n))
    kinds = np.resize(np.array(TILE_KINDS), n)[rng.permutation(n)]
    world = np.empty((rows * tile, cols * tile), np.float32)
    ramp = np.linspace(-1.0, 1.0, tile, dtype=np.float32)
    for k in range(n):
        r, c = divmod(k, cols)
        level = levels[k]
        if kinds[k] == "flat":
            block = np.full((tile, tile), level, np.float32)
        elif kinds[k] == "gradient":
            span = min(level - 2.0, 253.0 - level, 60.0)
            g = ramp[None, :] if rng.random() < 0.5 else ramp[:, None]
            block = np.broadcast_to(level + span * g, (tile, tile)).astype(np.float32)
        else:
            amp = min(level - 2.0, 253.0 - level, 35.0)
            tex = cv2.GaussianBlur(rng.standard_normal((tile, tile)).astype(np.float32), (0, 0), tile / 16.0)
            block = level + amp * tex / max(float(np.abs(tex).max()), 1e-6)
        world[r * tile:(r + 1) * tile, c * tile:(c + 1) * tile] = block
    return np.clip(world[:wh, :ww], 0.0, 255.0)


def camera_path(u: np.ndarray, moving: bool) -> np.ndarray:
    """Camera position in [0, 1]^2 (fraction of the pan range) at campaign times ``u`` in [0, 1].

    A moving camera alternates static stretches with pans; a static one stays at the centre.
    """
    u = np.asarray(u, dtype=float)
    if not moving:
        return np.full(u.shape + (2,), 0.5)
    keys = np.array([0.0, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9, 1.0])
    xs = np.array([0.0, 0.0, 1.0, 1.0, 0.3, 0.3, 0.0, 0.0])
    ys = np.array([0.0, 0.0, 0.3, 0.3, 1.0, 1.0, 0.5, 0.5])
    return np.stack([np.interp(u, keys, xs), np.interp(u, keys, ys)], axis=-1)


def view(world: np.ndarray, position: np.ndarray, height: int, width: int) -> tuple[np.ndarray, tuple[int, int]]:
    """The (height, width) window at ``position`` (fractions of the pan range) and its pixel offset."""
    x = int(round(float(position[0]) * (world.shape[1] - width)))
    y = int(round(float(position[1]) * (world.shape[0] - height)))
    return world[y:y + height, x:x + width], (x, y)
