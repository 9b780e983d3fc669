"""The per-frame table of a bag as Arrow/Parquet (numbers kept as the replay's float32, bit for bit),
and the campaign's table merged from the bags' files one bag at a time."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from noise_monitor.bag.results import CONDITION_KEYS, FrameTable
from noise_monitor.bag.staging import write_atomic

try:
    import pyarrow as pa
    import pyarrow.parquet as pq
except ImportError:  # the command still lists; running it says what to install
    pa = pq = None

if TYPE_CHECKING:
    import pyarrow as pa

#: Leading columns of every per-frame table; the conditions and the monitor's numbers (float32) follow.
BASE_COLUMNS = ("hardware_id", "bag", "sha256", "index", "stamp_ns", "time", "processed", "level", "alarm",
                "alarm_state", "cause", "skip_reason", "xi_measurement", "hold_event")


def require_pyarrow() -> None:
    if pa is None:
        raise ValueError("campaign tables are Parquet files: install pyarrow (pip install 'noise_monitor[fleet]')")


def to_arrow(table: FrameTable, hardware_id: str, sha256: str) -> pa.Table:
    """One row per frame; numeric columns float32, NaN where a frame has no value (as in the FrameTable).

    No bag path: a bag's file is keyed by its content, which several paths may share (the merge adds it)."""
    n = len(table)
    stamps = table.column("stamp_ns")
    cols: dict[str, pa.Array] = {
        "hardware_id": pa.array([hardware_id] * n, pa.string()),
        "sha256": pa.array([sha256] * n, pa.string()),
        "index": pa.array(table.column("index"), pa.int64()),
        "stamp_ns": pa.array(stamps, pa.int64()),
        "time": pa.array(stamps, pa.int64()).cast(pa.timestamp("ns", tz="UTC")),
        "processed": pa.array(table.column("processed"), pa.bool_()),
        "level": pa.array(table.column("level"), pa.int8()),
        "alarm": pa.array(table.column("alarm"), pa.bool_()),
        **{name: pa.array(table.texts(name), pa.string()) for name in FrameTable.TEXTS},
    }
    for key in (*CONDITION_KEYS, *table.number_keys):
        cols[key] = pa.array(table.numbers(key).astype(np.float32), pa.float32())  # float32 -> 64 -> 32 is exact
    return pa.table(cols)


def write_parquet(tab: pa.Table, path: Path) -> None:
    """Write atomically (a temporary file renamed into place)."""
    write_atomic(path, lambda fh: pq.write_table(tab, fh))


def merge(parts: Iterable[tuple[Path, str]], path: Path) -> int:
    """Concatenate per-bag Parquet files (file, bag path) into one: a row group per bag, one bag in memory.

    Columns missing from a bag (e.g. an extra source only some profiles have, or a text column a part written
    by an older version lacks) are NaN there (texts: null). Returns rows.
    """
    parts = list(parts)
    schemas = [pq.read_schema(p) for p, _ in parts]
    fields = {f.name: f for s in schemas for f in s}
    fields["bag"] = pa.field("bag", pa.string())
    names = [n for n in BASE_COLUMNS if n in fields]  # parts of an older version may lack a base column
    for s in schemas:
        names += [n for n in s.names if n not in names]
    schema = pa.schema([fields[n] for n in names])
    return write_atomic(path, lambda fh: _write_parts(parts, schema, fh))  # an interrupt leaves no half-written table


def _write_parts(parts: list[tuple[Path, str]], schema: pa.Schema, sink: Any) -> int:
    """The parts, each with its bag column and the columns it lacks, into ``sink`` (a binary file); returns rows."""
    rows = 0
    with pq.ParquetWriter(sink, schema) as writer:
        for p, bag in parts:
            tab = pq.read_table(p)
            for i, name in enumerate(schema.names):
                if name == "bag":
                    tab = tab.add_column(i, schema.field(name), pa.array([bag] * tab.num_rows, pa.string()))
                elif name not in tab.column_names:
                    field = schema.field(name)
                    missing = (pa.nulls(tab.num_rows, field.type) if pa.types.is_string(field.type)
                               else pa.array(np.full(tab.num_rows, np.nan, np.float32)))
                    tab = tab.add_column(i, field, missing)
            writer.write_table(tab.select(schema.names).cast(schema))
            rows += tab.num_rows
    return rows
