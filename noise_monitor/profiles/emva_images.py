"""EMVA 1288 image sets: a descriptor file and the images it lists, read as a :class:`Recording`.

The exchange format of EMVA 1288 measurements (the EMVA's reference datasets, its reference implementation
``emva1288``, labs' own rigs) is a text file beside the images::

    v 3.0                      # the standard's release the measurement followed
    n 12 640 480               # bits per pixel, width, height
    b 40000.0 120.0            # a bright set: exposure time (ns), photons per pixel
    i images\\b_000_snap_001.tif
    i images\\b_000_snap_002.tif
    d 40000.0                  # a dark set at that exposure
    i images\\d_000_snap_001.tif
    ...

``#`` starts a comment, ``l`` a line for the report template (kept as information). Two images make a set for
the temporal noise (the photon transfer curve, linearity), more a set for the spatial noise (DSNU, PRNU). Paths
are relative to the descriptor's folder (``\\`` or ``/``). Images are 8- or 16-bit single-channel files (PNG, TIFF,
PGM, ...), the codes of the stated bit depth.
The sets' kind (bright or dark) is the file's, not guessed from their level; their photon counts give the
quantum efficiency that a recording without a calibrated irradiance cannot.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from noise_monitor.bag.messages import image_msg, metadata_msg
from noise_monitor.bag.writer import BagWriter
from noise_monitor.physics import CameraProfile, MetadataError

from .characterize import CharacterizeError, FrameSet, Recording

#: Exposure units a descriptor's times may be in (the format's own is ns).
EXPOSURE_UNITS = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
DESCRIPTOR_NAME = "EMVA1288_Data.txt"


@dataclass
class Block:
    """One ``b`` or ``d`` line and its images."""

    kind: str  # "flat" (b) or "dark" (d)
    exposure: float  # in the descriptor's unit
    photons: float | None
    line: int
    files: list[Path] = field(default_factory=list)


@dataclass
class Descriptor:
    path: Path
    bits: int
    width: int
    height: int
    version: str | None
    blocks: list[Block]
    info: dict[str, str]


def find_descriptor(path: str | Path) -> Path | None:
    """The descriptor a path names: the file itself when it is one, or the one descriptor in a folder; None when
    the path is no EMVA image set (a bag, say)."""
    p = Path(path)
    if p.is_file():
        return p if p.suffix.lower() == ".txt" else None
    if not p.is_dir() or any(p.glob("metadata.yaml")) or any(p.glob("*.db3")) or any(p.glob("*.mcap")):
        return None
    named = p / DESCRIPTOR_NAME
    if named.is_file():
        return named
    found = [t for t in sorted(p.glob("*.txt")) if _looks_like_descriptor(t)]
    if len(found) > 1:
        raise CharacterizeError(f"{p}: several EMVA 1288 descriptor files ({', '.join(t.name for t in found)}): "
                                "name the one to read")
    return found[0] if found else None


def _looks_like_descriptor(path: Path) -> bool:
    with path.open(errors="replace") as f:
        return any(line.split()[:1] == ["n"] for line in f)


def _number(text: str, where: str) -> float:
    try:
        return float(text.replace(",", "."))
    except ValueError:
        raise CharacterizeError(f"{where}: {text!r} is not a number") from None


def parse_descriptor(path: str | Path) -> Descriptor:
    """The descriptor's lines checked: clear errors name the file and line."""
    path = Path(path)
    fmt: tuple[int, int, int] | None = None
    version = None
    blocks: list[Block] = []
    info: dict[str, str] = {}
    for no, raw in enumerate(path.read_text(errors="replace").splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{path.name} line {no}"
        key, *args = line.split(None, 1)
        rest = args[0].split() if args else []
        if key == "v" and len(rest) == 1:
            version = rest[0]
        elif key == "n":
            if len(rest) != 3 or not all(r.isdigit() for r in rest):
                raise CharacterizeError(f"{where}: 'n' takes bits, width and height, got {line!r}")
            if fmt is not None:
                raise CharacterizeError(f"{where}: a second 'n' line (one image format per file)")
            fmt = (int(rest[0]), int(rest[1]), int(rest[2]))
            if not 1 <= fmt[0] <= 16:
                raise CharacterizeError(f"{where}: {fmt[0]} bits per pixel (1..16 are read)")
        elif key == "b" and len(rest) == 2:
            blocks.append(Block("flat", _number(rest[0], where), _number(rest[1], where), no))
        elif key == "d" and len(rest) == 1:
            blocks.append(Block("dark", _number(rest[0], where), None, no))
        elif key == "i" and args:
            if not blocks:
                raise CharacterizeError(f"{where}: an image before any 'b' or 'd' line")
            blocks[-1].files.append(path.parent.joinpath(*args[0].strip().replace("\\", "/").split("/")))
        elif key == "l" and args:
            name, _, value = args[0].partition(" ")
            info[name] = value.strip()
        else:
            raise CharacterizeError(f"{where}: {line!r} is not an EMVA 1288 descriptor line ('v', 'n bits width "
                                    "height', 'b exposure photons', 'd exposure', 'i image', 'l name value')")
    if fmt is None:
        raise CharacterizeError(f"{path}: no 'n bits width height' line: not an EMVA 1288 descriptor file")
    for b in blocks:
        if len(b.files) < 2:
            raise CharacterizeError(f"{path.name} line {b.line}: a set needs two images or more, it lists "
                                    f"{len(b.files)}")
        if b.exposure < 0 or (b.photons is not None and b.photons < 0):
            raise CharacterizeError(f"{path.name} line {b.line}: a negative exposure or photon count")
    return Descriptor(path, *fmt, version, blocks, info)


def _image(file: Path, d: Descriptor) -> np.ndarray:
    if not file.is_file():
        raise CharacterizeError(f"{d.path.name}: image {file} not found")
    a = cv2.imread(str(file), cv2.IMREAD_UNCHANGED)
    if a is None:
        raise CharacterizeError(f"{file}: not readable as an image")
    if a.ndim != 2 or a.dtype.kind != "u":
        raise CharacterizeError(f"{file}: a single-channel integer image is needed, got shape {a.shape}, {a.dtype}")
    if a.shape != (d.height, d.width):
        raise CharacterizeError(f"{file} is {a.shape[1]}x{a.shape[0]} pixels, the descriptor states "
                                f"{d.width}x{d.height}")
    top = int(a.max())
    if top > 2**d.bits - 1:
        raise CharacterizeError(f"{file}: code {top} above the {d.bits}-bit range the descriptor states (codes "
                                "stored shifted to the container's top bits? store them as the ADC gave them)")
    return a


def read_image_set(path: str | Path, exposure_unit: str = "ns", temperature_c: float | None = None,
                   gain_db: float = 0.0) -> Recording:
    """An EMVA 1288 image set (its descriptor file or the folder holding it) as a :class:`Recording` (images on the
    8-bit scale, each set's kind and photons from the descriptor). ``temperature_c``: the sensor's during the
    measurement (the format has none)."""
    if exposure_unit not in EXPOSURE_UNITS:
        raise CharacterizeError(f"exposure unit {exposure_unit!r}: one of {', '.join(EXPOSURE_UNITS)}")
    descriptor = find_descriptor(path)
    if descriptor is None:
        raise CharacterizeError(f"{path}: no EMVA 1288 descriptor file (a .txt with an 'n bits width height' line)")
    d = parse_descriptor(descriptor)
    if not d.blocks:
        raise CharacterizeError(f"{d.path}: no 'b' or 'd' set listed")
    scale = 255.0 / (2**d.bits - 1)
    sets, frames = [], 0
    for b in d.blocks:
        s = FrameSet(gain_db, b.exposure * EXPOSURE_UNITS[exposure_unit], temperature_c, first_index=frames,
                     kind=b.kind, photons=b.photons, temporal=len(b.files) == 2)
        for file in b.files:
            s.add(_image(file, d).astype(np.float64) * scale)
        frames += len(b.files)
        s.compute()
        sets.append(s)
    static = {"emva_release": d.version, **({"info": d.info} if d.info else {})}
    return Recording(sets, d.bits, (d.height, d.width), frames, {}, static, kinds_given=True)


def flat_blocks(d: Descriptor) -> list[Block]:
    """The flat-field sets in the order a flats bag holds them: the temporal pairs by photon count, then the spatial
    sets."""
    flats = [b for b in d.blocks if b.kind == "flat"]
    return sorted((b for b in flats if len(b.files) == 2), key=lambda b: b.photons or 0.0) + [
        b for b in flats if len(b.files) > 2]


def write_flats_bag(path: str | Path, out: str | Path, profile: CameraProfile, exposure_unit: str = "ns",
                    temperature_c: float = 25.0, fps: float = 10.0, start_ns: int = 1_700_000_000_000_000_000
                    ) -> tuple[int, dict[int, str]]:
    """An EMVA image set's flat fields as a bag to replay through the monitor (``camera/image_raw``: mono8 or mono16;
    ``camera/metadata``: the profile's metadata at each frame's exposure, 0 dB, ``temperature_c``): the temporal
    pairs by photon count, then the spatial sets (:func:`flat_blocks`), each a static hold. Returns the frames written
    and the sets left out (metadata the model refuses, e.g. an exposure of 0 s): the reason by descriptor line."""
    descriptor = find_descriptor(path)
    if descriptor is None:
        raise CharacterizeError(f"{path}: no EMVA 1288 descriptor file")
    d = parse_descriptor(descriptor)
    count, left_out = 0, {}
    with BagWriter(out) as w:
        for b in flat_blocks(d):
            try:
                meta = profile.metadata(gain_db=0.0, exposure_time_s=b.exposure * EXPOSURE_UNITS[exposure_unit],
                                        sensor_temperature_c=temperature_c)
            except MetadataError as exc:
                left_out[b.line] = f"{len(b.files)} images: {exc}"
                continue
            for file in b.files:
                stamp = start_ns + int(count * 1e9 / fps)
                w.write("/camera/metadata", metadata_msg(meta, stamp, f"emva1288/{descriptor.parent.name}"), stamp)
                w.write("/camera/image_raw", image_msg(_image(file, d), stamp), stamp)
                count += 1
    return count, left_out
