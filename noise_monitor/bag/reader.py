"""Read camera bags (rosbag2 MCAP or sqlite3 directories, bare .mcap/.db3 files) into monitor frames.

Topics are found by message type unless given: the image topic (sensor_msgs/msg/Image; a
sensor_msgs/msg/CompressedImage topic when the bag has no raw one: lossless PNG/zstd frames are decoded,
lossy ones skipped with the reason), the metadata
topic (a DiagnosticArray, a known vendor metadata type, any type with fields named like
CameraMetadata fields, or camera_ros's libcamera metadata on /diagnostics), CameraInfo and Temperature.
Message definitions stored in the bag are registered (rosbags typesys), so vendor types deserialise without
their packages installed.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_typestore

from msg_adapters import AdapterError, camera_geometry, prepare_frame
from msg_adapters.keymap import KeyMapEntry, metadata_from_json_keymap, metadata_from_keymap, parse_keymap
from msg_adapters.libcamera import is_libcamera, metadata_from_camera_ros
from msg_adapters.metadata import (
    ALIASES,
    KNOWN_FIELDS,
    metadata_from_diagnostics,
    metadata_from_mapping,
    metadata_from_temperature,
)
from msg_adapters.outputs import DEBUG_IMAGE, DIAGNOSTICS_TOPIC, FRAME
from msg_adapters.vendor import HELD_TYPES, KEYMAP_TYPES, VENDOR_TYPES, metadata_from_vendor, register_vendor_types
from noise_monitor import safe_yaml
from noise_monitor.monitor.frame import Frame
from noise_monitor.monitor.runtime import FrameOptions
from noise_monitor.monitor.sync import match_stamp
from noise_monitor.physics import CameraProfile, load_profile
from noise_monitor.text import clip

from . import bounded
from .errors import BagError

IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_TYPE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TEMPERATURE_TYPE = "sensor_msgs/msg/Temperature"
DIAGNOSTIC_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
_METADATA_NAMES = frozenset(KNOWN_FIELDS) | frozenset(ALIASES)
#: messages of a DiagnosticArray topic read to tell whether it carries camera_ros's libcamera metadata, and of which
#: cameras
PEEK_MESSAGES = 200
bounded.install()  # MCAP chunks are decompressed within limits (decompression bombs are refused)


def _reason(exc: BaseException) -> str:
    """An exception from rosbags as a bounded one-line reason."""
    return clip(" ".join(str(exc).split()) or type(exc).__name__)


@dataclass(frozen=True)
class DamagedMessage:
    """Stands in for a message whose bytes do not decode (the reason names it)."""

    reason: str


#: the suffixes of bag files: rosbag2's MCAP and sqlite3 storage, ROS 1 bags
BAG_SUFFIXES = (".mcap", ".db3", ".bag")


def _header_ns(msg: Any) -> int | None:
    """Header stamp of a message in ns; None when it has no (or a zero) header stamp."""
    st = getattr(getattr(msg, "header", None), "stamp", None)
    ns = None if st is None else int(st.sec) * 1_000_000_000 + int(st.nanosec)
    return ns if ns is not None and ns > 0 else None


def _stamp_ns(msg: Any, log_time: int) -> int:
    """Header stamp of a message in ns; the log time when it has no (or a zero) header stamp."""
    ns = _header_ns(msg)
    return int(log_time) if ns is None else ns


def _resolve_bag_path(path: Path) -> Path:
    """The bag path rosbags should open: a rosbag2 dir, or the single storage file of a dir without
    metadata.yaml (e.g. a copied MCAP folder), or a bare .mcap/.db3 file, or a ROS 1 .bag file."""
    if not path.exists():
        raise FileNotFoundError(f"bag {path} does not exist")
    if path.is_dir() and (path / "metadata.yaml").is_file():
        try:  # rosbags parses it again; this is the bounded check (alias bombs, size) with a clear reason
            safe_yaml.load(path / "metadata.yaml")
        except safe_yaml.YamlError as exc:
            raise BagError(f"cannot read bag {path}: {exc}") from None
    if path.is_dir() and not (path / "metadata.yaml").exists():
        files = sorted([*path.glob("*.mcap"), *path.glob("*.db3")])
        if len(files) != 1:
            raise BagError(f"{path} is a folder without metadata.yaml and {len(files)} .mcap/.db3 files; "
                           "pass the bag file itself")
        return files[0]
    if path.is_file() and path.suffix.lower() not in BAG_SUFFIXES:
        raise BagError(f"{path}: not a bag (expected a rosbag2 folder, a .mcap, .db3 or ROS 1 .bag file)")
    if path.is_file() and path.suffix != path.suffix.lower():  # rosbags tells the storage by the suffix
        raise BagError(f"{path}: rosbags reads bag files by their lower-case suffix: rename it to "
                       f"{path.with_suffix(path.suffix.lower()).name}")
    return path


class BagReader:
    """An opened bag with its detected topics. Iterate :meth:`frames`; ``len()`` = number of images."""

    def __init__(self, path: str | Path, image_topic: str | None = None, metadata_topic: str | None = None,
                 camera_info_topic: str | None = None, temperature_topic: str | None = None,
                 detect_topics: bool = True) -> None:
        self.path = Path(path)
        self._bag_path = _resolve_bag_path(self.path)
        store = get_typestore(Stores.ROS2_JAZZY)
        register_vendor_types(store)
        try:
            self._reader = AnyReader([self._bag_path], default_typestore=store)
            self._reader.open()
        except Exception as exc:  # rosbags: own, struct, zstd, decoding errors
            raise BagError(f"cannot read bag {self.path}: {_reason(exc)} (corrupt or truncated?)") from None
        self.topics: dict[str, str] = {c.topic: c.msgtype for c in self._reader.connections}
        if not self.topics or self._reader.message_count == 0:
            self.close()
            raise BagError(f"bag {self.path} is empty (no messages)")
        self.image_topic = self.metadata_topic = self.camera_info_topic = self.temperature_topic = None
        #: the libcamera camera ids in the metadata topic when it is camera_ros's /diagnostics (else empty)
        self.libcamera_ids: tuple[str, ...] = ()
        if not detect_topics:  # raw access only (playback of every topic)
            return
        try:
            self.image_topic = self._pick("image", image_topic, self._image_candidates(), required=True)
            self.metadata_topic = self._pick("metadata", metadata_topic, self._metadata_candidates())
            if self.metadata_topic is not None and self.topics[self.metadata_topic] == DIAGNOSTIC_TYPE:
                self.libcamera_ids = self._libcamera_ids(self.metadata_topic)
            self.camera_info_topic = self._pick("camera_info", camera_info_topic, self._typed(CAMERA_INFO_TYPE))
            self.temperature_topic = self._pick("temperature", temperature_topic, self._typed(TEMPERATURE_TYPE))
        except BagError:
            self.close()
            raise

    # --- topic detection ----------------------------------------------------------------------
    def _typed(self, msgtype: str) -> list[str]:
        """The topics of this type that hold messages (all of them where none does): a topic recorded without
        messages (``ros2 bag record -a`` keeps every advertised one) is no candidate."""
        topics = sorted(t for t, m in self.topics.items() if m == msgtype)
        return [t for t in topics if self.count([t])] or topics

    def _image_candidates(self) -> list[str]:
        plain, compressed = self._typed(IMAGE_TYPE), self._typed(COMPRESSED_TYPE)
        imgs = plain if plain and (self.count(plain) or not self.count(compressed)) else compressed
        camera = [t for t in imgs if not t.endswith(f"/{DEBUG_IMAGE}")]  # not a recorded monitor's debug view
        imgs = camera or imgs
        raw = [t for t in imgs if t.endswith("image_raw") or t.endswith("image_raw/compressed")]
        return raw if len(raw) == 1 else imgs

    def _metadata_candidates(self) -> list[str]:
        diag = [t for t in self._typed(DIAGNOSTIC_TYPE) if "metadata" in t]
        if diag:
            return diag
        vendor = sorted(t for t, m in self.topics.items() if m in VENDOR_TYPES)
        if vendor:
            return vendor
        fielddefs = self._reader.typestore.fielddefs
        generic = sorted(t for t, m in self.topics.items() if m not in (IMAGE_TYPE, CAMERA_INFO_TYPE, TEMPERATURE_TYPE)
                         and m in fielddefs and _METADATA_NAMES & {f[0] for f in fielddefs[m][1]})
        if generic:
            return generic
        diag = [t for t in self._typed(DIAGNOSTIC_TYPE)  # not the monitor's own outputs (a recorded node)
                if t != DIAGNOSTICS_TOPIC and not t.endswith(f"/{FRAME}")]
        if not diag and DIAGNOSTICS_TOPIC in self.topics and self._libcamera_ids(DIAGNOSTICS_TOPIC):
            return [DIAGNOSTICS_TOPIC]  # camera_ros: libcamera's metadata among every node's diagnostics
        return diag

    def _libcamera_ids(self, topic: str) -> tuple[str, ...]:
        """The camera ids of the libcamera metadata statuses (camera_ros) among the first PEEK_MESSAGES messages of a
        DiagnosticArray topic, in order of appearance (none: it is not camera_ros's)."""
        ids: dict[str, None] = {}
        for i, (_, _, msg) in enumerate(self.messages([topic])):
            if i == PEEK_MESSAGES:
                break
            for status in getattr(msg, "status", None) or ():
                if is_libcamera(status):
                    ids.setdefault(str(status.hardware_id).strip(), None)
        return tuple(ids)

    def _pick(self, role: str, override: str | None, candidates: list[str], required: bool = False) -> str | None:
        if override:
            if override not in self.topics:
                raise BagError(f"{role} topic {clip(repr(override), 200)} is not in bag {self.path}; topics: {self._listing()}")
            return override
        if len(candidates) > 1 and self.image_topic:  # prefer the image's namespace (e.g. /left/...)
            ns = self.image_topic.rsplit("/", 1)[0] + "/"
            same = [t for t in candidates if t.startswith(ns)]
            candidates = same if len(same) == 1 else candidates
        if len(candidates) > 1:
            raise BagError(f"several {role} topics in bag {self.path}: {clip(', '.join(candidates))}; "
                           f"choose one with --{role.replace('_', '-')}-topic")
        if not candidates and required:
            raise BagError(f"no {role} topic ({IMAGE_TYPE} or {COMPRESSED_TYPE}) in bag {self.path}; "
                           f"topics: {self._listing()}")
        return candidates[0] if candidates else None

    def _listing(self) -> str:
        return clip(", ".join(f"{t} [{m}]" for t, m in sorted(self.topics.items())) or "none")

    # --- info ------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.count([self.image_topic]) if self.image_topic else 0

    def count(self, topics: list[str]) -> int:
        """Number of messages on these topics."""
        return sum(c.msgcount for c in self._reader.connections if c.topic in topics)

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time)

    @property
    def duration_s(self) -> float:
        """Log time from the first to the last message of the bag (s)."""
        return max(0, self._reader.end_time - self._reader.start_time) / 1e9

    def _conns(self, topic: str | None) -> list[Connection]:
        return [c for c in self._reader.connections if c.topic == topic]

    def hardware_id(self) -> str | None:
        """The driver's device id: the ``hardware_id`` of the first metadata message's first status (a
        DiagnosticArray; camera_ros: its one camera's libcamera id), or None."""
        if self.metadata_topic is None:
            return None
        if self.libcamera_ids:  # several cameras: none of them is the bag's
            return (self.libcamera_ids[0] or None) if len(self.libcamera_ids) == 1 else None
        for _, _, msg in self.messages([self.metadata_topic]):
            status = getattr(msg, "status", None)
            return (str(status[0].hardware_id).strip() or None) if status else None
        return None

    def messages(self, topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time ns, deserialised message) in log-time order.

        A message whose bytes do not decode is yielded as a :class:`DamagedMessage` (the frames it
        concerns are skipped with its reason); damaged bag structure (records, chunks, index) that stops
        reading is a BagError.
        """
        conns = [c for t in topics for c in self._conns(t)]
        it = self._reader.messages(connections=conns)
        expected, seen = self.count(topics), 0
        while True:
            try:
                conn, log_time, raw = next(it)
            except StopIteration:
                if seen < expected:  # damaged records are skipped silently by rosbags
                    raise BagError(f"bag {self.path} is damaged: read {seen} of the {expected} messages its index "
                                   f"lists on {', '.join(topics)}") from None
                return
            except Exception as exc:  # rosbags: own, struct, zstd, decoding errors
                raise BagError(f"bag {self.path} is damaged: {_reason(exc)}") from None
            try:
                if raw is None:  # a sqlite3 row whose data is NULL
                    raise ValueError("it has no data (NULL)")
                msg = self._reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # rosbags: own, struct, zstd, decoding errors
                size = f"{len(raw)} bytes" if raw is not None else "no data"
                msg = DamagedMessage(f"damaged {clip(conn.msgtype, 200)} message ({size}) on {clip(conn.topic, 200)} "
                                     f"at log time {log_time} ns does not decode: {_reason(exc)}")
            seen += 1
            yield conn.topic, log_time, msg

    def raw_messages(self, topics: list[str] | None = None) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, message type, log time ns, CDR bytes) in log-time order, without deserialising; a ROS 1 bag holds
        no CDR bytes (a BagError)."""
        if not self._reader.is2:
            raise BagError(f"{self.path} is a ROS 1 bag, whose messages are not ROS 2's bytes: convert it first "
                           "(rosbags-convert --src BAG.bag --dst FOLDER) to publish it")
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        it = self._reader.messages(connections=conns)
        while True:
            try:
                conn, log_time, raw = next(it)
            except StopIteration:
                return
            except Exception as exc:  # rosbags: own, struct, zstd, decoding errors
                raise BagError(f"bag {self.path} is damaged: {_reason(exc)}") from None
            if raw is None:  # a sqlite3 row whose data is NULL: nothing to publish
                raise BagError(f"bag {self.path} is damaged: the {clip(conn.msgtype, 200)} message on "
                               f"{clip(conn.topic, 200)} at log time {log_time} ns has no data (NULL)")
            yield conn.topic, conn.msgtype, log_time, bytes(raw)

    @property
    def message_count(self) -> int:
        return int(self._reader.message_count)

    def _metadata_of(self, msg: Any, profile: CameraProfile | None = None,
                     keymap: Sequence[KeyMapEntry] | None = None, camera: str = "") -> dict[str, Any] | None:
        mtype = getattr(msg, "__msgtype__", "")
        if mtype == DIAGNOSTIC_TYPE and self.libcamera_ids:
            return metadata_from_camera_ros(msg, camera)  # None: another node's diagnostics or another camera's
        if mtype == DIAGNOSTIC_TYPE:
            return metadata_from_keymap(msg, keymap, profile) if keymap else metadata_from_diagnostics(msg)
        if mtype in KEYMAP_TYPES:
            return metadata_from_json_keymap(msg, keymap or [], profile)
        if mtype in VENDOR_TYPES:
            return metadata_from_vendor(msg, profile)
        return metadata_from_mapping({k: getattr(msg, k) for k in _METADATA_NAMES if hasattr(msg, k)})

    def _timeline(self, topic: str | None, convert) -> _Timeline:
        """The converted values of a small side topic by time, errors kept as AdapterError; messages that convert to
        None (not this camera's) left out."""
        if topic is None:
            return _Timeline([], [], False)
        items, unstamped = [], False
        for _, log_time, msg in self.messages([topic]):
            try:
                if isinstance(msg, DamagedMessage):
                    raise AdapterError(msg.reason)
                value: Any = convert(msg)
            except (AdapterError, ValueError) as exc:
                value = AdapterError(f"{topic}: {exc}")
            if value is not None:
                stamp = _header_ns(msg)
                unstamped |= stamp is None
                items.append((int(log_time) if stamp is None else stamp, int(log_time), value))
        at = 1 if unstamped else 0  # a topic without header stamps is matched by the time it was recorded
        items.sort(key=lambda x: x[at])
        return _Timeline([x[at] for x in items], [x[2] for x in items], unstamped)

    # --- frames ----------------------------------------------------------------------------------
    def frames(self, profile: CameraProfile | str | Path | None = None, bit_depth: int | None = None,
               sync_tolerance_s: float = 0.01, color: str = "luma",
               metadata_keymap: Sequence[str] | None = None, black_level_dn: float | None = None,
               hardware_id: str = "") -> Iterator[Frame]:
        """Yield every image as a :class:`Frame` in log-time order, prepared as the node prepares it
        (``msg_adapters.prepare_frame``).

        Metadata follows the monitor's matching rule (:func:`noise_monitor.monitor.sync.match_stamp`: the
        message nearest the image stamp within ``sync_tolerance_s``, else the latest older one; a driver whose values
        are held until its next message, Basler's and camera_aravis2's, the latest at or before the image, its age not
        judged, as the node holds them); it is merged
        over ``profile`` (dynamic values win) and the Temperature matched the same way. Unusable
        CameraInfo/Temperature messages are ignored. ``Frame.skip_reason`` says why a frame cannot be
        evaluated (``image unusable: ...``, ``metadata invalid: ...``, ``metadata missing: ...``). Driver
        metadata messages (:mod:`msg_adapters.vendor`) are converted with the profile (relative gains);
        ``metadata_keymap`` (``STATUS|KEY|FIELD|UNIT[|SCALE]`` entries) reads a DiagnosticArray of a
        driver's own key names, or Orbbec's JSON frame metadata (:mod:`msg_adapters.keymap`; a bad entry is a ValueError). ``black_level_dn``: the
        black level taken off every image (default: the profile's). camera_ros's libcamera metadata on /diagnostics
        (:mod:`msg_adapters.libcamera`) is read from its camera's statuses, ``hardware_id``'s when several cameras
        publish there (a BagError naming them without it).
        """
        if len(self.libcamera_ids) > 1 and hardware_id not in self.libcamera_ids:
            raise BagError(f"bag {self.path}: {self.metadata_topic} carries the libcamera metadata of several cameras "
                           f"({clip(', '.join(self.libcamera_ids))}): name one with the node parameter hardware_id"
                           + (f" (not {clip(repr(hardware_id), 80)})" if hardware_id else ""))
        prof = load_profile(profile) if isinstance(profile, (str, Path)) else profile
        options = FrameOptions(prof, bit_depth, color, black_level_dn)
        keymap = parse_keymap(metadata_keymap) if metadata_keymap else None
        camera = hardware_id if self.libcamera_ids and hardware_id in self.libcamera_ids else ""
        meta = self._timeline(self.metadata_topic, lambda m: self._metadata_of(m, prof, keymap, camera))
        temps = self._timeline(self.temperature_topic, metadata_from_temperature)
        infos = self._timeline(self.camera_info_topic, camera_geometry)
        held = self.metadata_topic is not None and self.topics[self.metadata_topic] in HELD_TYPES
        tol = int(sync_tolerance_s * 1e9)
        if self.image_topic is None:
            raise BagError(f"bag {self.path} was opened without topic detection: no image topic")
        for index, (_, log_time, msg) in enumerate(self.messages([self.image_topic])):
            stamp = _stamp_ns(msg, log_time)
            mi = meta.match(stamp, int(log_time), 0 if held else tol)
            temp = _usable(temps.value(temps.match(stamp, int(log_time), tol)))
            yield prepare_frame(
                msg, stamp, options, metadata=meta.values[mi] if mi is not None else None,
                metadata_stamp_ns=meta.stamp_for(mi, stamp, int(log_time)) if mi is not None and not held else None,
                temperature_c=temp["sensor_temperature_c"] if temp else None,
                geometry=_usable(infos.value(infos.match(stamp, int(log_time), tol))),
                image_error=msg.reason if isinstance(msg, DamagedMessage) else None,
                index=index, log_time_ns=int(log_time))

    def close(self) -> None:
        if getattr(self._reader, "stack", None):
            self._reader.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _usable(value: Any) -> Any:
    """A side-topic value, or None when its message could not be converted."""
    return None if isinstance(value, Exception) else value


@dataclass
class _Timeline:
    """A side topic's values by time: their header stamps, or where the driver does not stamp them (a zero or no
    header stamp) the times they were recorded, matched with the image's (until 2026-12-04 such metadata, timed by
    its recording, was matched against the images' header stamps: the previous frame's gain for every frame)."""

    times: list[int]
    values: list[Any]
    by_log_time: bool

    def match(self, stamp_ns: int, log_time_ns: int, tolerance_ns: int) -> int | None:
        """The index of the value for an image of this header stamp and log time (:func:`match_stamp`)."""
        return match_stamp(self.times, log_time_ns if self.by_log_time else stamp_ns, tolerance_ns)

    def value(self, i: int | None) -> Any:
        return self.values[i] if i is not None else None

    def stamp_for(self, i: int, stamp_ns: int, log_time_ns: int) -> int:
        """Value i's time on the image's header clock (for its age)."""
        return stamp_ns - (log_time_ns - self.times[i]) if self.by_log_time else self.times[i]


def open_bag(path: str | Path, image_topic: str | None = None, metadata_topic: str | None = None,
             camera_info_topic: str | None = None, temperature_topic: str | None = None) -> BagReader:
    """Open a bag and detect its topics (see :class:`BagReader`); raises BagError for unusable bags."""
    return BagReader(path, image_topic=image_topic, metadata_topic=metadata_topic,
                     camera_info_topic=camera_info_topic, temperature_topic=temperature_topic)
