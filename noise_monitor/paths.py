"""Locate the package's data folders (config/, bags/) in a source checkout or a ROS install."""
from __future__ import annotations

import sys
from pathlib import Path

_SOURCE_ROOT = Path(__file__).resolve().parent.parent


def share_dir() -> Path:
    """Folder holding config/, launch/ and bags/: the source checkout, a pip install's
    ``<prefix>/share/noise_monitor``, else the ament share dir of a ROS install."""
    for root in (_SOURCE_ROOT, Path(sys.prefix) / "share" / "noise_monitor"):
        if (root / "config" / "cameras").is_dir():
            return root
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("noise_monitor"))
    except Exception as exc:  # pragma: no cover - only without a source tree and without ament
        raise FileNotFoundError("cannot find noise_monitor's config/ folder") from exc


def camera_profile_path(name_or_path: str | Path) -> Path:
    """Resolve a profile given as a file or as a bundled name like 'icx285' (a bare name: a path that names no
    existing file is an error, never a bundled profile of the same stem)."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    bundled = share_dir() / "config" / "cameras"
    if p.name == str(name_or_path) and not p.suffix:
        candidate = bundled / f"{p.name.lower()}.yaml"
        if candidate.exists():
            return candidate
        raise FileNotFoundError(f"camera profile {name_or_path!r} not found (neither a file nor a bundled profile: "
                                f"{', '.join(sorted(c.stem for c in bundled.glob('*.yaml')))})")
    raise FileNotFoundError(f"camera profile file {name_or_path!r} not found")
