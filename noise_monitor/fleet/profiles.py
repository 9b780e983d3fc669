"""Which camera profile a bag uses: one ``--profile`` for all, or a map from camera (hardware_id) to profile.

A profile map is YAML::

    cameras:                      # hardware_id (as in the bag's metadata messages) or a glob pattern
      robot1/front: ev76c661      # bundled profile name ...
      robot2/*: cams/robot2.yaml  # ... or a profile YAML (relative to the map file)
    default: generic              # optional: cameras not listed (without it they are reported, not evaluated)
"""
from __future__ import annotations

from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

import yaml


class ProfileMapError(ValueError):
    """The profile map file is unusable, or a camera is not in it."""


def _spec(value: Any, base: Path, where: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ProfileMapError(f"{where}: a profile must be a bundled name or a YAML path, got {value!r}")
    p = base / value
    return str(p.resolve()) if value.endswith((".yaml", ".yml")) and not Path(value).is_absolute() else value


@dataclass(frozen=True)
class ProfileMap:
    """hardware_id -> profile spec (bundled name or absolute YAML path)."""

    cameras: dict[str, str] = field(default_factory=dict)
    default: str | None = None
    source: str = "--profile"

    @classmethod
    def single(cls, profile: str | None) -> ProfileMap:
        """Every camera with one profile (None: all metadata from the bags)."""
        return cls({}, profile, "--profile")

    @classmethod
    def load(cls, path: str | Path) -> ProfileMap:
        p = Path(path)
        try:
            doc = yaml.safe_load(p.read_text())
        except OSError as exc:
            raise ProfileMapError(f"profile map {p}: cannot read ({exc.strerror or exc})") from None
        except yaml.YAMLError as exc:
            raise ProfileMapError(f"profile map {p}: not valid YAML ({' '.join(str(exc).split())})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("cameras", {}), dict):
            raise ProfileMapError(f"profile map {p}: expected a mapping with 'cameras: {{hardware_id: profile}}'")
        unknown = set(doc) - {"cameras", "default"}
        if unknown:
            raise ProfileMapError(f"profile map {p}: unknown keys {', '.join(sorted(map(str, unknown)))} "
                                  "(allowed: cameras, default)")
        base = p.parent
        cameras = {str(k): _spec(v, base, f"profile map {p}, camera {k!r}") for k, v in doc.get("cameras", {}).items()}
        default = _spec(doc["default"], base, f"profile map {p}, default") if doc.get("default") is not None else None
        if not cameras and default is None:
            raise ProfileMapError(f"profile map {p}: no cameras and no default")
        return cls(cameras, default, str(p))

    def resolve(self, hardware_id: str | None) -> str | None:
        """The profile of a camera: exact id, then the first matching pattern, then the default."""
        if hardware_id is not None:
            if hardware_id in self.cameras:
                return self.cameras[hardware_id]
            for pattern, spec in self.cameras.items():
                if fnmatchcase(hardware_id, pattern):
                    return spec
        if self.default is not None or not self.cameras:
            return self.default
        who = f"camera {hardware_id!r}" if hardware_id else "a bag without a hardware_id in its metadata"
        raise ProfileMapError(f"{who} is not in the profile map {self.source} (and the map has no default)")
