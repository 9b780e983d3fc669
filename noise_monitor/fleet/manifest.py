"""The campaign manifest: one JSON line per finished (or failed) bag, appended and fsync'ed as it ends.

A line is written only after the bag's outputs are in place, so an interrupted campaign (Ctrl-C, a killed
driver) leaves a manifest that names exactly the bags whose outputs are complete; a torn last line is
ignored on reading. Entries are keyed by the bag's content hash and the campaign settings: a re-run with
the same settings skips finished bags (found by path, size and mtime without re-hashing them).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, BinaryIO

MANIFEST = "manifest.jsonl"


class Manifest:
    """Finished bags of a campaign output folder."""

    def __init__(self, out_dir: Path, settings_key: str) -> None:
        self.path = out_dir / MANIFEST
        self.settings_key = settings_key
        self.entries: dict[str, dict[str, Any]] = {}  # bag path -> latest entry with these settings
        self.torn_lines = 0  # lines that do not parse (a kill mid-write)
        if self.path.is_file():
            with open(self.path, encoding="utf-8") as fh:
                for line in fh:
                    try:
                        entry = json.loads(line)
                    except ValueError:
                        self.torn_lines += 1
                        continue
                    if isinstance(entry, dict) and entry.get("settings") == settings_key and "path" in entry:
                        self.entries[entry["path"]] = entry
        self._fh: BinaryIO | None = None

    def finished(self, path: str, size: int, mtime_ns: int) -> dict[str, Any] | None:
        """The entry of a bag finished with these settings and unchanged since, else None."""
        e = self.entries.get(path)
        if e and e["status"] == "ok" and e["size"] == size and e["mtime_ns"] == mtime_ns:
            return e
        return None

    def record(self, entry: dict[str, Any]) -> None:
        """Append one entry durably (flush + fsync): a crash after this call keeps it."""
        entry = {**entry, "settings": self.settings_key}
        fh = self._fh
        if fh is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fh = self._fh = open(self.path, "a+b")
            fh.seek(0, os.SEEK_END)
            if fh.tell():
                fh.seek(-1, os.SEEK_END)
                torn = fh.read(1) != b"\n"
                fh.seek(0, os.SEEK_END)
            else:
                torn = False
            if torn:  # a torn last line (a kill mid-write): start ours on a fresh line
                fh.write(b"\n")
        fh.write((json.dumps(entry, separators=(",", ":")) + "\n").encode())
        fh.flush()
        os.fsync(fh.fileno())
        self.entries[entry["path"]] = entry

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
