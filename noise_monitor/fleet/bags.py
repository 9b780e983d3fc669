"""Find the bags of a campaign, fingerprint them cheaply and hash their content."""
from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from ..bag.reader import BAG_SUFFIXES

_CHUNK = 1 << 20


@dataclass(frozen=True)
class Problem:
    """An input that is not evaluated, with the reason."""

    path: str
    reason: str


def _bag_files(bag: Path) -> list[Path]:
    """The files whose bytes make up a bag (a rosbag2 folder: all its files, sorted)."""
    if bag.is_dir():
        return sorted(p for p in bag.rglob("*") if p.is_file())
    return [bag]


def fingerprint(bag: Path) -> tuple[int, int]:
    """(total size in bytes, newest mtime in ns): unchanged bags keep it, so a re-run need not re-hash them."""
    files = _bag_files(bag)
    stats = [f.stat() for f in files]
    return sum(s.st_size for s in stats), max((s.st_mtime_ns for s in stats), default=0)


def content_hash(bag: Path) -> str:
    """sha256 of a bag's bytes (a folder: its files' relative names and contents, in sorted order)."""
    h = hashlib.sha256()
    for f in _bag_files(bag):
        if bag.is_dir():
            h.update(str(f.relative_to(bag)).encode() + b"\0")
        with open(f, "rb") as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
    return h.hexdigest()


def _walk(root: Path, skip: Path | None = None) -> Iterable[Path]:
    """Bags below a folder: rosbag2 folders (metadata.yaml; not descended into) and bare .mcap/.db3/.bag files;
    ``skip``: a folder not searched (the campaign's own outputs, which hold replayed bags)."""
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if skip is not None and d.resolve() == skip:
            dirnames[:] = []
            continue
        if "metadata.yaml" in filenames:
            dirnames[:] = []
            yield d
            continue
        dirnames.sort()
        for name in sorted(filenames):
            if name.lower().endswith(BAG_SUFFIXES):
                yield d / name


def find_bags(inputs: Iterable[str | Path], skip: str | Path | None = None) -> tuple[list[Path], list[Problem]]:
    """Bags named by ``inputs`` (bag files, rosbag2 folders, folders searched recursively), each once; a folder's
    search leaves out ``skip`` (the campaign's output folder: its per-bag replays are no recordings).

    Paths that do not exist, files that are not bags, folders without bags and links to a bag found before are
    problems, not errors (a path named twice is counted once).
    """
    skipped = Path(skip).resolve() if skip is not None else None
    bags: list[Path] = []
    seen: dict[Path, Path] = {}  # resolved path -> the path it was first found as
    problems: list[Problem] = []
    for raw in inputs:
        p = Path(raw)
        if not p.exists():
            problems.append(Problem(str(p), "does not exist"))
            continue
        if p.is_file():
            found = [p] if p.suffix.lower() in BAG_SUFFIXES else []
            if not found:
                problems.append(Problem(str(p), "not a bag (expected a rosbag2 folder, a .mcap, .db3 or ROS 1 .bag file)"))
        else:
            found = list(_walk(p, skipped))
            if not found:
                problems.append(Problem(str(p), "folder holds no bag (.mcap, .db3, .bag or a rosbag2 folder)"))
        for bag in found:
            key = bag.resolve()
            if key not in seen:
                seen[key] = bag
                bags.append(bag)
            elif bag.absolute() != seen[key].absolute():  # a link to a bag found before (not the same path again)
                problems.append(Problem(str(bag), f"duplicate of {seen[key]} (the same file, linked): counted once"))
    return bags, problems
