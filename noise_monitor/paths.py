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
    """Resolve a profile given as a path or as a bundled name like 'icx285'."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    candidate = share_dir() / "config" / "cameras" / f"{p.stem.lower()}.yaml"
    if candidate.exists():
        return candidate
    raise FileNotFoundError(
        f"camera profile {name_or_path!r} not found (neither a file nor a bundled profile in "
        f"{share_dir() / 'config' / 'cameras'})"
    )
