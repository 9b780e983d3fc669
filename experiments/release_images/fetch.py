"""Images of earlier releases of the allowed packages, as a second set of unseen images for `evaluate --images`.

matplotlib 1.5.3 shipped three sample images the current release no longer has (``ada.png``: an engraved
portrait; ``ct.raw.gz``: a 512x512 CT slice, 12 bits in 16-bit words; ``necked_tensile_specimen.png``: a rendered
mesh) and scikit-image 0.14.2 a close-up photograph of a rough wall (``rough-wall.png``). None is in the training or
tuning imagery, the held-out ``photos`` or any earlier figure of this project. This script downloads the two wheels
from the package index (``pip download --no-deps``; the index is the only network needed), checks each file
against its SHA-256 and writes the four images into ``--out`` (the CT slice as a 16-bit PNG, which
``evaluate --images`` stretches to 0..255 like any 16-bit image).

Usage: .venv/bin/python experiments/release_images/fetch.py --out out/release_images
       .venv/bin/noise-monitor evaluate --variants full_meta --images out/release_images --patches 1000 \
           --patch-size 64 --no-peers --no-sweep
"""
from __future__ import annotations

import argparse
import gzip
import hashlib
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

#: wheel -> {member: SHA-256 of the member}
WHEELS = {
    ("matplotlib==1.5.3", "--python-version", "2.7", "--platform", "manylinux1_x86_64"): {
        "matplotlib/mpl-data/sample_data/ada.png": "5f586324ad7fd4d73c0cdf841217b2dc6ed2abc8c1c100ca352978702004d2e6",
        "matplotlib/mpl-data/sample_data/necked_tensile_specimen.png":
            "ee72ef96dba92a67072181be7982a2ca3cd438df9c4aed189879c111785db479",
        "matplotlib/mpl-data/sample_data/ct.raw.gz": "2c3bef807fa6c9c4501760f6f7ec39316f78648d28a6fc0a528148f1eb8da4c9",
    },
    ("scikit-image==0.14.2", "--python-version", "3.6", "--platform", "manylinux1_x86_64"): {
        "skimage/data/rough-wall.png": "59c641fabbb70ba50b47660ce385fffb2da2a7f0b9e5e4184e882c3094bb4207",
    },
}
#: SHA-256 of the CT slice's raw bytes (512 x 512 little-endian uint16, values 0..3691)
CT_RAW_SHA256 = "fad5248f1134e901e3948cd9c0720df7c5d749d370ab0f1118cde24938517aa0"
CT_SHAPE = (512, 512)


def _download(spec: tuple[str, ...], into: Path) -> Path:
    """The wheel of ``spec`` (requirement and target platform) downloaded into ``into``."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary", ":all:", "-d", str(into), *spec]
    if subprocess.run(cmd, stdout=subprocess.DEVNULL).returncode:
        raise SystemExit(f"pip could not download {spec[0]} (no network to the package index?): {' '.join(cmd)}")
    name = spec[0].split("==")[0].replace("-", "_")
    wheels = sorted(into.glob(f"{name}-{spec[0].split('==')[1]}-*.whl"))
    if not wheels:
        raise SystemExit(f"pip left no wheel for {spec[0]} in {into}")
    return wheels[0]


def _checked(data: bytes, sha256: str, what: str) -> bytes:
    """``data`` when its SHA-256 is ``sha256``; exits naming ``what`` otherwise."""
    if hashlib.sha256(data).hexdigest() != sha256:
        raise SystemExit(f"{what}: SHA-256 {hashlib.sha256(data).hexdigest()} is not the expected {sha256}")
    return data


def extract(wheels: dict[tuple[str, ...], dict[str, str]], out: Path, write: Callable[[str, bytes, Path], str]) -> None:
    """Every member of ``wheels`` (wheel spec -> {member: SHA-256}) downloaded, checked and written into ``out`` by
    ``write(file name, bytes, out)``, which returns the name of the file it wrote."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for spec, members in wheels.items():
            with zipfile.ZipFile(_download(spec, Path(tmp))) as wheel:
                for member, sha in members.items():
                    name = write(Path(member).name, _checked(wheel.read(member), sha, member), out)
                    print(f"wrote {out / name}")


def _write(name: str, data: bytes, out: Path) -> str:
    """A member as it is, the CT slice as a 16-bit PNG."""
    if name != "ct.raw.gz":
        (out / name).write_bytes(data)
        return name
    raw = _checked(gzip.decompress(data), CT_RAW_SHA256, "ct.raw")
    cv2.imwrite(str(out / "ct.png"), np.frombuffer(raw, dtype="<u2").reshape(CT_SHAPE))
    return "ct.png"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/release_images"))
    extract(WHEELS, ap.parse_args().out, _write)


if __name__ == "__main__":
    main()
