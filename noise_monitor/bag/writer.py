"""Write rosbag2 bags with rosbags: MCAP (default, a bare ``.mcap`` file or a bag directory) or sqlite3.

A path ending in ``.mcap`` with ``storage="mcap"`` gives one self-contained MCAP file (what Foxglove,
the ``mcap`` library and ``ros2 bag play`` open directly); any other path gives a rosbag2 directory
(``metadata.yaml`` plus the storage file), the layout ``ros2 bag record`` produces.
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys.store import Typestore

from msg_adapters.diagnostics import jazzy_typestore as typestore

from .errors import BagError

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


class BagWriter:
    """Context manager writing rosbags messages; connections are added on first use of a topic, or up front
    (:meth:`declare`) for a node's publishers that may send nothing (as ``ros2 bag record`` keeps them)."""

    def __init__(self, path: str | Path, storage: str = "mcap", compress: bool = True,
                 store: Typestore | None = None) -> None:
        if storage not in STORAGES:
            raise BagError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already; choose a new output path or delete it")
        self.storage = storage
        self.bare = storage == "mcap" and self.path.suffix == ".mcap"
        self.store = store or typestore()
        self._compress = compress
        self._tmp: Path | None = None
        self._writer: Writer | None = None
        self._connections: dict[tuple[str, str], Any] = {}
        self.counts: dict[str, int] = {}

    def __enter__(self) -> BagWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        target = self.path
        if self.bare:
            self._tmp = Path(tempfile.mkdtemp(prefix=".bagwrite-", dir=self.path.parent))
            target = self._tmp / self.path.stem
        self._writer = Writer(target, version=9, storage_plugin=STORAGES[self.storage])
        if self._compress:
            # MCAP: zstd chunk compression (readers decompress transparently); sqlite3: none
            if self.storage == "mcap":
                self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.open()
        return self

    def declare(self, topics: dict[str, str]) -> None:
        """Add the connections of ``topics`` ({topic: message type}) before any message."""
        for topic, msgtype in topics.items():
            self._connection(topic, msgtype)

    def _connection(self, topic: str, msgtype: str) -> Any:
        assert self._writer is not None, "use BagWriter as a context manager"
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            conn = self._connections[key] = self._writer.add_connection(topic, msgtype, typestore=self.store)
        return conn

    def write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Serialise ``msg`` (a rosbags message of ``self.store``) on ``topic`` with log time ``stamp_ns``."""
        assert self._writer is not None, "use BagWriter as a context manager"
        msgtype = msg.__msgtype__
        self._writer.write(self._connection(topic, msgtype), int(stamp_ns), self.store.serialize_cdr(msg, msgtype))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self._writer is not None
        try:
            self._writer.close()
            if self.bare and exc is None:
                assert self._tmp is not None
                inner = self._tmp / self.path.stem / f"{self.path.stem}.mcap"
                shutil.move(str(inner), str(self.path))
        finally:
            if self._tmp is not None:
                shutil.rmtree(self._tmp, ignore_errors=True)
            if exc is not None and self.path.exists():  # never leave a half-written bag behind
                shutil.rmtree(self.path) if self.path.is_dir() else self.path.unlink()
