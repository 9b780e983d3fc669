"""Parameters -> a configured monitor: the one runtime shared by the live node, the bag replay and the lab.

The node declares :func:`parameter_table` as ROS parameters; replay reads the same table from a params
file (default ``config/node.yaml``) plus command-line overrides; the lab uses the defaults. Either way
:class:`MonitorRuntime` turns the values into the camera profile, the noise model (the profile's effects
included), the estimator (loaded once), the :class:`Monitor` and the :class:`FrameOptions` with which
``msg_adapters.prepare_frame`` converts messages into :class:`Frame` objects.
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from noise_monitor.physics import CameraProfile, NoiseModel, load_profile
from noise_monitor.physics.metadata import BLACK_LEVEL_MAX_DN
from noise_monitor.physics.table_grid import GridSpec
from noise_monitor.text import clip

from .config import DESCRIPTIONS, MonitorConfig, read_ros_params
from .frame import Frame
from .pipeline import RUNTIME_SETTABLE, Estimator, FrameResult, Monitor

COLORS = ("luma", "green")
#: the node's parameters that ``ros2 param set`` may change while it runs (the monitor's settings and the black level)
SETTABLE_PARAMETERS = (*RUNTIME_SETTABLE, "black_level_dn")
#: Parameters of the runtime beyond MonitorConfig: name -> (default, description).
RUNTIME_PARAMETERS: dict[str, tuple[Any, str]] = {
    "image_topic": ("image", "sensor_msgs/Image input (sensor-data QoS); relative names resolve in the node's "
                             "namespace and are remappable"),
    "image_transport": ("raw", "raw (sensor_msgs/Image) or compressed (sensor_msgs/CompressedImage on "
                               "image_topic/compressed as image_transport names it, or on image_topic when it ends "
                               "in /compressed, /compressedDepth or /zstd: lossless PNG/TIFF/zstd decoded, lossy "
                               "formats refused as skipped frames)"),
    "metadata_topic": ("metadata", "per-frame metadata (type per metadata_source); '' = none"),
    "metadata_source": ("diagnostics", "diagnostics (DiagnosticArray with CameraMetadata key names), keymap "
                                       "(DiagnosticArray through metadata_keymap), flir, basler, realsense, aravis (the "
                                       "driver's metadata message, aravis: camera_aravis2's CameraDiagnostics on its "
                                       "~/diagnostics; its ROS package must be importable), orbbec (the stream's "
                                       "JSON metadata through metadata_keymap), camera_ros (libcamera's "
                                       "metadata on /diagnostics: set metadata_topic /diagnostics) or parameters (the "
                                       "driver node's /parameter_events)"),
    "metadata_keymap": ("", "key map 'STATUS|KEY|FIELD|UNIT[|SCALE]; ...' (FIELD: exposure_time_s, gain_db, "
                            "sensor_temperature_c; UNIT: s ms us 100us ns, dB factor relative, degC K)"),
    "metadata_driver_node": ("", "metadata_source parameters: the driver node's fully qualified name"),
    "metadata_driver": ("v4l2_camera", "metadata_source parameters: parameter names of v4l2_camera or usb_cam "
                                       "(metadata_keymap overrides)"),
    "camera_info_topic": ("camera_info", "sensor_msgs/CameraInfo (image size/binning/ROI check); '' = none"),
    "temperature_topic": ("temperature", "sensor_msgs/Temperature with the sensor temperature in degC (optional: "
                                         "without messages the metadata's or the profile's); '' = none"),
    "camera_name": ("", "camera name in the diagnostic status name 'noise_monitor: <camera_name>'; '' = the node's "
                        "namespace (cam1 for /cam1, two cameras stay apart), else 'camera'"),
    "hardware_id": ("", "diagnostic hardware_id; '' = the driver's (its metadata status's hardware_id, e.g. the "
                        "serial), else '<profile name>/<camera_name>'; with metadata_source camera_ros and several "
                        "cameras on /diagnostics, set it: only that camera's metadata is read"),
    "profile": ("", "camera profile with the static metadata: bundled name or YAML path; '' = metadata topic only"),
    "bit_depth": (0, "bits per pixel in 16-bit images; 0 = the frame's metadata's bit_depth, else the profile's, "
                     "else the container width"),
    "black_level_dn": (-1.0, "the camera's black level (pedestal, 8-bit DN scale; settable at run time) taken off "
                             "every image before the model reads it (overrides the metadata's per frame); -1 = the "
                             "frame's metadata black_level_dn, else the profile's (0 without)"),
    "color": ("luma", "reduction of colour images to gray: luma or green"),
    "model": ("full_meta", "estimator variant (noise_monitor.estimator.load)"),
    "weights": ("", "estimator checkpoint (.pt written by `noise-monitor train`); '' = the bundled weights"),
    "device": ("cpu", "inference device: cpu, cuda or auto"),
    "threads": (0, "CPU threads for inference; 0 = all cores but one (keeps one for message handling)"),
    "max_rate_hz": (0.0, "evaluate at most this many frames per second (others are dropped); 0 = no limit"),
    "sync_tolerance_s": (0.01, "image and metadata header stamps closer than this belong together"),
    "sync_wait_s": (0.1, "an image waits this long for its metadata, then takes the latest older one"),
    "expected_rate_hz": (0.0, "the camera's frame rate, for an exact frames_lost count; 0 = inferred from stamp gaps"),
    "diagnostics_rate_hz": (1.0, "minimum /diagnostics rate, also without images (STALE)"),
    "debug_image_rate_hz": (1.0, "~/debug_image (the frame with its patches outlined, coloured by their xi) at most "
                                 "this often; 0 = off"),
    "physics_tables": ("interpolated", "physics tables per metadata set: interpolated over gain, exposure and "
                                       "temperature (metadata that changes every frame) or exact (recomputed per set)"),
}
PHYSICS_TABLES = ("interpolated", "exact")
#: camera_name when neither the parameter nor a namespace names the camera.
DEFAULT_CAMERA_NAME = "camera"
#: Table requests per frame are 2-3 (monitor, estimator prior, temporal): metadata held for about 2 frames or
#: more gets exact tables, metadata drifting every frame interpolated ones (see GridSpec.held_exact_requests).
HELD_EXACT_REQUESTS = 4
#: Accepted diagnostics_rate_hz: from one report every 1000 s (slower is no heartbeat, and 1e-320 Hz would
#: overflow the period) to 1000 per second (a timer faster than this only burns CPU).
MIN_DIAGNOSTICS_RATE_HZ, MAX_DIAGNOSTICS_RATE_HZ = 1e-3, 1000.0


def parameter_table() -> dict[str, tuple[Any, str]]:
    """Every parameter: the runtime's plus each MonitorConfig field (same defaults and descriptions)."""
    defaults = MonitorConfig()
    table = dict(RUNTIME_PARAMETERS)
    for name in MonitorConfig.field_names():
        table[name] = (getattr(defaults, name), DESCRIPTIONS[name])
    return table


def coerce(name: str, value: Any, default: Any) -> Any:
    """A parameter value as the type of its default (ints accepted for floats); clear error otherwise."""
    kind = type(default)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind) or isinstance(value, bool) != isinstance(default, bool):
        raise ValueError(f"parameter {name} must be of type {kind.__name__}, got {clip(repr(value), 80)}")
    return value


def check_parameters(p: Mapping[str, Any]) -> None:
    """Range checks of the runtime parameters (MonitorConfig checks its own)."""
    if p["color"] not in COLORS:
        raise ValueError(f"parameter color must be luma or green, got {clip(repr(p['color']), 80)}")
    for name in ("max_rate_hz", "sync_tolerance_s", "sync_wait_s", "expected_rate_hz", "threads", "bit_depth",
                 "debug_image_rate_hz"):
        if not p[name] >= 0 or not math.isfinite(p[name]):
            raise ValueError(f"parameter {name} must be a finite number >= 0, got {p[name]}")
    if p["bit_depth"] > 16:
        raise ValueError(f"parameter bit_depth must be in 0..16, got {p['bit_depth']}")
    if not (p["black_level_dn"] == -1.0 or 0.0 <= p["black_level_dn"] < BLACK_LEVEL_MAX_DN):
        raise ValueError(f"parameter black_level_dn must be -1 (the profile's) or in [0, {BLACK_LEVEL_MAX_DN:g}) DN, "
                         f"got {p['black_level_dn']}")
    if not MIN_DIAGNOSTICS_RATE_HZ <= p["diagnostics_rate_hz"] <= MAX_DIAGNOSTICS_RATE_HZ:
        raise ValueError(f"parameter diagnostics_rate_hz must be in [{MIN_DIAGNOSTICS_RATE_HZ:g}, "
                         f"{MAX_DIAGNOSTICS_RATE_HZ:g}] Hz, got {p['diagnostics_rate_hz']}")
    if not p["image_topic"]:
        raise ValueError("parameter image_topic must not be empty")
    if p["image_transport"] not in ("raw", "compressed"):
        raise ValueError(f"parameter image_transport must be raw or compressed, got {p['image_transport']!r}")
    if p["physics_tables"] not in PHYSICS_TABLES:
        raise ValueError(f"parameter physics_tables must be interpolated or exact, got {p['physics_tables']!r}")


def resolve_parameters(values: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Defaults overridden by ``values``, type-coerced and range-checked; unknown names are an error."""
    table = parameter_table()
    values = dict(values or {})
    unknown = sorted(set(values) - set(table))
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(unknown)}")
    params = {name: coerce(name, values.get(name, default), default) for name, (default, _) in table.items()}
    check_parameters(params)
    return params


def inference_threads(threads: int) -> int:
    """CPU threads for inference: ``threads``, or all cores but one when 0 (one stays for messages)."""
    if threads < 0:
        raise ValueError(f"threads must be >= 0, got {threads}")
    return threads or max(1, (os.cpu_count() or 2) - 1)


def set_inference_threads(threads: int) -> None:
    """torch intra-op threads (see :func:`inference_threads`)."""
    import torch

    torch.set_num_threads(inference_threads(threads))


@dataclass(frozen=True)
class FrameOptions:
    """How messages become frames: static metadata, bit depth of 16-bit images, colour reduction."""

    profile: CameraProfile | None = None
    bit_depth: int | None = None  # stated by the user (parameter, --bit-depth); None: see :meth:`depth`
    color: str = "luma"
    black_level_dn: float | None = None  # taken off every image; None: the frame's metadata's, else the profile's

    def depth(self, stated: Any = None) -> int | None:
        """Bits per pixel of 16-bit images: the user's, else the frame's metadata's (``stated``, when an integer in
        1..16: a wrong one is the metadata's error, reported there), else the profile's."""
        if self.bit_depth:
            return self.bit_depth
        if isinstance(stated, (int, float)) and float(stated).is_integer() and 1 <= stated <= 16:
            return int(stated)
        return self.profile.bit_depth if self.profile is not None else None

    @property
    def black_level(self) -> float:
        """The configured black level (8-bit DN): this one, else the profile's, else 0 (a frame's metadata may report
        its own: :func:`msg_adapters.frames.black_level`)."""
        if self.black_level_dn is not None:
            return self.black_level_dn
        return self.profile.black_level_dn if self.profile is not None else 0.0


class MonitorRuntime:
    """Resolved parameters, profile, noise model, estimator and the :class:`Monitor` of one camera.

    ``profile`` (a CameraProfile or a name/path) and ``estimator`` override the parameters' choice;
    ``model`` replaces the profile's noise model (the lab compares models); ``config`` replaces the
    MonitorConfig built from the parameters.
    """

    def __init__(self, params: Mapping[str, Any] | None = None, *, profile: CameraProfile | str | Path | None = None,
                 estimator: Estimator | None = None, model: NoiseModel | None = None,
                 config: MonitorConfig | None = None) -> None:
        p = resolve_parameters(params)
        self.params = p
        self.config = config or MonitorConfig.from_mapping({k: p[k] for k in MonitorConfig.field_names()})
        if isinstance(profile, CameraProfile):
            self.profile: CameraProfile | None = profile
        else:
            name = profile or p["profile"]
            self.profile = load_profile(name) if name else None
        interpolate = GridSpec(held_exact_requests=HELD_EXACT_REQUESTS) if p["physics_tables"] == "interpolated" else False
        self.model = model or NoiseModel(extra=self.profile.effects if self.profile else None, interpolate=interpolate)
        threads = inference_threads(p["threads"])
        if "torch" in sys.modules or p["device"] != "cpu":  # torch runs (or will run) inference
            set_inference_threads(threads)
        if estimator is None:  # the estimator's physics prior is this camera's model
            from noise_monitor.estimator import load

            estimator = load(p["model"], device=p["device"], weights=p["weights"] or None, model=self.model,
                             threads=threads)
        self.estimator = estimator
        profile_name = self.profile.name if self.profile else "unknown"
        p["camera_name"] = p["camera_name"] or DEFAULT_CAMERA_NAME
        self.hardware_id = p["hardware_id"] or f"{profile_name}/{p['camera_name']}"
        self.monitor = Monitor(self.config, estimator, self.model, p["camera_name"], self.hardware_id)
        depth = int(p["bit_depth"]) or None
        #: keys of a params file's every-node sections that are not the monitor's (:meth:`from_params_file`)
        self.params_ignored: list[str] = []
        self.frame_options = FrameOptions(self.profile, depth, p["color"],
                                          None if p["black_level_dn"] == -1.0 else float(p["black_level_dn"]))

    def set_black_level(self, black_level_dn: float) -> None:
        """The black level taken off every image from now on (-1: the frame's metadata's, else the profile's)."""
        self.frame_options = dataclasses.replace(self.frame_options,
                                                 black_level_dn=None if black_level_dn == -1.0 else float(black_level_dn))
        self.params["black_level_dn"] = black_level_dn

    @classmethod
    def from_params_file(cls, path: str | Path | None = None, overrides: Mapping[str, Any] | None = None,
                         **kwargs: Any) -> MonitorRuntime:
        """The runtime of a ROS params file (default: the package's config/node.yaml) with ``overrides``
        (e.g. command-line options; None values are ignored). Keys of the file's every-node sections that are not
        the monitor's (other nodes'; a typo?) are in :attr:`params_ignored`."""
        ignored: list[str] = []
        params = read_ros_params(path, known=parameter_table(), ignored=ignored)
        params.update({k: v for k, v in (overrides or {}).items() if v is not None})
        runtime = cls(params, **kwargs)
        runtime.params_ignored = sorted(set(ignored))
        return runtime

    @property
    def diagnostics_period_ns(self) -> int:
        return int(1e9 / self.params["diagnostics_rate_hz"])

    def process(self, frame: Frame, received_ns: int | None = None) -> FrameResult:
        """One frame through the monitor."""
        return self.monitor.process(frame, received_ns=received_ns)
