"""MonitorConfig: the tunable constants of the per-frame pipeline (also node parameters)."""
from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from noise_monitor.physics.constants import MIN_PATCH, MODES

from .. import safe_yaml
from ..text import clip

#: the node's default name (``ros2 run``, ``noise-monitor node``; ``-r __node:=...`` renames it)
NODE_NAME = "noise_monitor"
#: parameters every rclpy node declares itself: a params file may set them for the monitor's node (rclpy's to read)
ROS_OWN_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service", "qos_overrides"})

XI_SOURCES = ("auto", "estimator", "model")
MODEL_MODES = MODES
ALARM_LEVELS = ("WARN", "ERROR")

#: One-line description per field (used for the node's declared parameters and --help texts).
DESCRIPTIONS: dict[str, str] = {
    "patches_per_frame": "patches (K) evaluated per frame, spread over the usable image area",
    "patch_size": "patch edge in pixels; 0 = the estimator's native patch size (128 = the paper's: steadier xi, ~4x cost)",
    "min_patch_mean_dn": "patches darker than this mean (DN) are skipped (underexposed: unreliable estimates)",
    "max_patch_mean_dn": "patches brighter than this mean (DN) are skipped (overexposed: unreliable estimates)",
    "max_clipped_fraction": "max fraction of pixels at 0 or 255 DN in a usable patch (black / saturated)",
    "max_flat_fraction": "max fraction of equal neighbour pixels in a usable patch (flat-clipped plateaus)",
    "smooth_fraction": "when there are more usable patches than needed, keep this least-textured fraction",
    "model_mode": "physics model mode for the predicted sigma: joint (physical camera) or sequential (paper)",
    "xi_source": "xi driving the alarm: estimator (its xi output), model (this analytic model incl. the profile's "
                 "effects - the estimated image noise) or auto (model when the profile adds effects, else estimator)",
    "xi_threshold_dn": "alarm when |filtered xi| exceeds this (DN)",
    "xi_hysteresis_dn": "alarm clears only below threshold - hysteresis (DN)",
    "alarm_min_frames": "consecutive processed frames with |filtered xi| beyond the threshold that raise the alarm",
    "alarm_evidence": "the alarm also rises when a CUSUM of (|xi| - threshold) / (xi's standard error) over the "
                      "frames (across views) reaches this (standard errors); 0 = off (count rule only)",
    "clear_min_frames": "consecutive processed frames below the clear level before the alarm clears",
    "filter_alpha": "exponential filter weight of a new frame (0..1] for xi and the per-source sigmas",
    "image_timeout_s": "no image for this long -> STALE",
    "metadata_timeout_s": "metadata older than this (relative to the image) -> WARN, frame not evaluated",
    "min_patches": "fewer usable patches than this -> WARN, frame not evaluated",
    "alarm_level": "diagnostic level of an xi alarm: WARN or ERROR",
    "temporal_frames": "frames of a static hold whose differences measure the temporal noise (sigma_temporal); "
                       "0 = off (single-image measurement only)",
    "temporal_min_frames": "frames a static hold needs before its temporal measurement enters xi",
    "image_xi_error_dn": "largest error (DN) of the single-image xi: a frame's own is its patches' predicted "
                         "error, at most this (the alarm's evidence unit, the weight against the temporal xi)",
}


@dataclass(frozen=True)
class MonitorConfig:
    """Constants of patch selection, aggregation, filtering, alarms and staleness."""

    patches_per_frame: int = 8
    patch_size: int = 0
    min_patch_mean_dn: float = 12.0
    max_patch_mean_dn: float = 243.0
    max_clipped_fraction: float = 0.01
    max_flat_fraction: float = 0.9
    smooth_fraction: float = 0.5
    model_mode: str = "joint"
    xi_source: str = "auto"
    xi_threshold_dn: float = 1.0
    xi_hysteresis_dn: float = 0.3
    alarm_min_frames: int = 5
    alarm_evidence: float = 3.0
    clear_min_frames: int = 10
    filter_alpha: float = 0.3
    image_timeout_s: float = 2.0
    metadata_timeout_s: float = 2.0
    min_patches: int = 1
    alarm_level: str = "ERROR"
    temporal_frames: int = 16
    temporal_min_frames: int = 4
    image_xi_error_dn: float = 0.3

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type == "int":
                if (isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
                        or float(value) != int(value)):
                    raise ValueError(f"{f.name} must be an integer, got {clip(repr(value), 80)}")
                object.__setattr__(self, f.name, int(value))
            elif f.type == "float":
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"{f.name} must be a finite number, got {clip(repr(value), 80)}")
                object.__setattr__(self, f.name, float(value))
        checks = [
            (self.patches_per_frame >= 1, "patches_per_frame must be >= 1"),
            (self.patch_size == 0 or self.patch_size >= MIN_PATCH,
             f"patch_size must be 0 (estimator's) or >= {MIN_PATCH} (the estimator's smallest patch)"),
            (0 <= self.min_patch_mean_dn < self.max_patch_mean_dn <= 255, "need 0 <= min_patch_mean_dn < max_patch_mean_dn <= 255"),
            (0 <= self.max_clipped_fraction <= 1, "max_clipped_fraction must be in [0, 1]"),
            (0 < self.max_flat_fraction <= 1, "max_flat_fraction must be in (0, 1]"),
            (0 < self.smooth_fraction <= 1, "smooth_fraction must be in (0, 1]"),
            (self.model_mode in MODEL_MODES, f"model_mode must be one of {MODEL_MODES}"),
            (self.xi_source in XI_SOURCES, f"xi_source must be one of {XI_SOURCES}"),
            (self.xi_threshold_dn > 0, "xi_threshold_dn must be > 0"),
            (0 <= self.xi_hysteresis_dn < self.xi_threshold_dn, "xi_hysteresis_dn must be in [0, xi_threshold_dn)"),
            (self.alarm_min_frames >= 1 and self.clear_min_frames >= 1, "alarm/clear_min_frames must be >= 1"),
            (self.alarm_evidence >= 0, "alarm_evidence must be >= 0 (0 = off)"),
            (0 < self.filter_alpha <= 1, "filter_alpha must be in (0, 1]"),
            (self.image_timeout_s > 0 and self.metadata_timeout_s > 0, "timeouts must be > 0"),
            (1 <= self.min_patches <= self.patches_per_frame, "min_patches must be in [1, patches_per_frame]"),
            (self.alarm_level in ALARM_LEVELS, f"alarm_level must be one of {ALARM_LEVELS}"),
            (self.temporal_frames == 0 or 2 <= self.temporal_frames <= 256, "temporal_frames must be 0 or in 2..256"),
            (2 <= self.temporal_min_frames, "temporal_min_frames must be >= 2"),
            (self.temporal_frames == 0 or self.temporal_min_frames <= self.temporal_frames,
             "temporal_min_frames must be <= temporal_frames (a window never holds more: no temporal measurement)"),
            (self.image_xi_error_dn > 0, "image_xi_error_dn must be > 0"),
        ]
        for ok, reason in checks:
            if not ok:
                raise ValueError(f"monitor config: {reason}")

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], ignore_unknown: bool = False) -> MonitorConfig:
        """Build from a mapping of field names (e.g. node parameters); unknown keys are an error."""
        names = set(cls.field_names())
        unknown = sorted(map(str, set(values) - names))
        if unknown and not ignore_unknown:
            raise ValueError(f"unknown monitor setting(s): {clip(', '.join(unknown))}; known: {', '.join(sorted(names))}")
        return cls(**{k: v for k, v in values.items() if k in names})

    @classmethod
    def from_yaml(cls, path: str | Path | None = None) -> MonitorConfig:
        """The monitor settings of a ROS params file (default: the package's config/node.yaml).

        Reads the ``ros__parameters`` of the first node entry and keeps the monitor's fields (other node
        parameters such as topic names are ignored here).
        """
        params = read_ros_params(path)
        return cls.from_mapping(params, ignore_unknown=True)


def default_params_path() -> Path:
    from ..paths import share_dir

    return share_dir() / "config" / "node.yaml"


def read_ros_params(path: str | Path | None = None, node_name: str = NODE_NAME, namespace: str | None = None,
                    known: Collection[str] | None = None, ignored: list[str] | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` a node named ``node_name`` takes from a ROS 2 params YAML file, later sections winning
    as in rcl: every section whose key names it (``noise_monitor``, ``/ns/noise_monitor``, ``/**/noise_monitor``) or
    every node (``/**``, ``/*``). A section's namespace must be ``namespace`` when one is given (the node's); without
    one, sections for the node in different namespaces are an error naming them. Keys of the every-node sections that
    are not ``known`` are other nodes' (left out, appended to ``ignored``: a typo there is the caller's to name);
    rclpy's own (``use_sim_time``, ``qos_overrides``) are rclpy's. A file with no section for the node is an error
    naming its sections."""
    p = Path(path) if path else default_params_path()
    if not p.exists():
        raise FileNotFoundError(f"parameter file {p} not found")
    doc = safe_yaml.load(p)
    usage = f"{p}: expected '<node name>: {{ros__parameters: {{...}}}}'"
    if not isinstance(doc, dict) or not doc:
        raise ValueError(usage)
    out: dict[str, Any] = {}
    spaces: set[str] = set()
    matched = False
    for key, node in doc.items():
        names = _section(str(key), node_name, namespace)
        if names is None:
            continue
        if not isinstance(node, dict) or not isinstance(node.get("ros__parameters"), dict):
            raise ValueError(usage)
        matched = True
        values = dict(node["ros__parameters"])
        if names == "every" and known is not None:
            others = [k for k in values if k not in known and k not in ROS_OWN_PARAMETERS]
            if ignored is not None:
                ignored.extend(others)
            values = {k: v for k, v in values.items() if k not in others}
        else:
            spaces.add(names)
        out.update(values)
    if not matched:
        raise ValueError(f"{p}: no section for the node {node_name!r} (sections: "
                         f"{clip(', '.join(map(str, doc)), 200)}; e.g. '/**' or '{node_name}')")
    if namespace is None and len(spaces - {"*"}) > 1:
        raise ValueError(f"{p}: sections for the node {node_name!r} in several namespaces "
                         f"({', '.join(sorted(spaces - {'*'}))}): give the namespace")
    return {k: v for k, v in out.items() if k not in ROS_OWN_PARAMETERS}


def _section(key: str, node_name: str, namespace: str | None) -> str | None:
    """What a params file's section key names of the node ``node_name``: ``"every"`` (``/**``, ``/*``), its namespace
    (``/ns``; ``*`` for a wildcard one, ``/`` for none), or None when it names another node or namespace (rcl's
    wildcards: ``*`` one name, ``**`` any)."""
    parts = [t for t in key.strip().strip("/").split("/") if t]
    if not parts or parts[-1] not in (node_name, "*", "**"):
        return None
    if parts[-1] != node_name:
        return "every" if len(parts) == 1 or namespace is None or _space_matches(parts[:-1], namespace) else None
    space = parts[:-1]
    if any(t in ("*", "**") for t in space):
        return "*" if namespace is None or _space_matches(space, namespace) else None
    name = "/" + "/".join(space)
    return name if namespace is None or name == "/" + namespace.strip("/") else None


def _space_matches(tokens: list[str], namespace: str) -> bool:
    """Whether namespace tokens with rcl's wildcards match a namespace."""
    pattern = "/".join("[^/]+" if t == "*" else ".*" if t == "**" else re.escape(t) for t in tokens)
    return re.fullmatch(pattern, namespace.strip("/")) is not None
