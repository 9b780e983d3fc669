"""Outputs of a run written safely into an output folder.

Files are first written under a new private folder inside the output folder, then moved to their names
with ``os.replace`` when the run succeeds: a name that is a symlink is replaced, never followed (nothing
outside the folder is overwritten), and a failed or interrupted run leaves the previous outputs as they
were and no temporary files. Outputs of the previous run that this run does not produce are removed, so
the folder never mixes two runs. An output that is the run's input is refused before anything is written.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import IO, Any, TypeVar

from .errors import BagError

T = TypeVar("T")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def input_files(path: str | Path) -> list[Path]:
    """The files a bag (or any input) consists of: the file itself, or every file of its folder."""
    p = Path(path)
    if p.is_dir():
        return [f for f in p.iterdir() if f.is_file()]
    return [p] if p.exists() else []


def refuse_overwriting_inputs(outputs: list[Path], inputs: list[Path]) -> None:
    """BagError when an output path is (or resolves to) one of the input files."""
    for out in outputs:
        for inp in inputs:
            if _same_file(out, inp) or out.resolve() == inp.resolve():
                raise BagError(f"output {out} is the input {inp}; choose another output folder")


class StagedOutputs:
    """Context manager: ``path(name)`` is where to write output ``name``; :meth:`commit` publishes them."""

    def __init__(self, folder: str | Path, names: list[str], inputs: list[Path] | None = None) -> None:
        self.folder = Path(folder)
        self.names = list(names)
        if self.folder.exists() and not self.folder.is_dir():
            raise BagError(f"output folder {self.folder} is not a folder")
        for inp in inputs or []:
            if inp.is_dir() and self.folder.resolve() == inp.resolve():
                raise BagError(f"output folder {self.folder} is the input bag folder {inp}; choose another one")
            refuse_overwriting_inputs([self.folder / n for n in self.names], input_files(inp))
        self._tmp: Path | None = None
        self._created = False

    def __enter__(self) -> StagedOutputs:
        self._created = not self.folder.exists()
        self.folder.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=".staging-", dir=self.folder))
        return self

    def path(self, name: str) -> Path:
        """Where to write output ``name`` (a fresh path in the private staging folder)."""
        assert self._tmp is not None and name in self.names, name
        return self._tmp / name

    def final(self, name: str) -> Path:
        return self.folder / name

    def commit(self) -> list[str]:
        """Move every written output to its name (replacing links and old files, never following them) and
        remove the previous run's outputs that were not written this time; returns the written names."""
        assert self._tmp is not None
        written = [n for n in self.names if (self._tmp / n).exists()]
        for name in written:
            os.replace(self._tmp / name, self.folder / name)
        for name in set(self.names) - set(written):
            stale = self.folder / name
            if stale.is_symlink() or stale.is_file():
                stale.unlink()
        return written

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
        if self._created and not any(self.folder.iterdir()):  # a failed run leaves no empty folder it made
            self.folder.rmdir()


def _umask() -> int:
    """The process's umask, read without setting it (``os.umask`` would change it for other threads meanwhile);
    022 where /proc does not tell."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    return 0o022


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write a text file atomically (:func:`write_atomic`)."""
    write_atomic(path, lambda fh: fh.write(text), "w")


def write_atomic(path: str | Path, write: Callable[[IO[Any]], T], mode: str = "wb") -> T:
    """Write a file by ``write(handle)`` into a new file in its folder, then ``os.replace`` (a symlink at ``path`` is
    replaced, not followed; an interrupted write leaves the old file and no temporary one); returns what ``write``
    returned."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", dir=p.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp's file is private (0600); the result gets a plain file's mode
        with os.fdopen(fd, mode) as fh:
            result = write(fh)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return result
