"""Images of packages the project never trained or tuned on, as a third set of unseen images for `evaluate --images`.

scipy 1.9.3 shipped a photograph of a raccoon in foliage (``scipy/misc/face.dat``: 768 x 1024 RGB, bz2-compressed raw
bytes; later releases download it instead) and mahotas 1.4.19 ships three demo images (``DepartmentStore.jpg``: a
dense illustrated crowd, ``luispedro.jpg``: a portrait, ``nuclear.png``: a fluorescence micrograph). This script
downloads the two wheels from the package index, checks each file against its SHA-256 (``release_images/fetch.py``'s
``extract``) and writes the four images into ``--out``.

Usage: .venv/bin/python experiments/other_package_images/fetch.py --out out/other_package_images
"""
from __future__ import annotations

import argparse
import bz2
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "release_images"))
from fetch import extract  # noqa: E402

#: wheel -> {member: SHA-256 of the member}
WHEELS = {
    ("scipy==1.9.3", "--python-version", "3.11", "--platform", "manylinux2014_x86_64"): {
        "scipy/misc/face.dat": "9d8b0b4d081313e2b485748c770472e5a95ed1738146883d84c7030493e82886",
    },
    ("mahotas==1.4.19", "--python-version", "3.11", "--platform", "manylinux_2_28_x86_64"): {
        "mahotas/demos/data/DepartmentStore.jpg": "1b6ae6ab0fd757370501368981f989fe7b1b6d0d7703028990a6bffe94cc67e0",
        "mahotas/demos/data/luispedro.jpg": "27e7af47501a4e9a06e4d8bd8b834bd773fe7b187baef2f47e120c663524bed1",
        "mahotas/demos/data/nuclear.png": "c0d3fc389d90a90118b43b585cd5134a560a7fcadb7b46825fc7845321755e27",
    },
}
FACE_SHAPE = (768, 1024, 3)


def _write(name: str, data: bytes, out: Path) -> str:
    """A member as it is, the raccoon's raw bytes as a PNG."""
    if name != "face.dat":
        (out / name).write_bytes(data)
        return name
    rgb = np.frombuffer(bz2.decompress(data), dtype=np.uint8).reshape(FACE_SHAPE)
    cv2.imwrite(str(out / "face.png"), np.ascontiguousarray(rgb[..., ::-1]))
    return "face.png"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/other_package_images"))
    extract(WHEELS, ap.parse_args().out, _write)


if __name__ == "__main__":
    main()
