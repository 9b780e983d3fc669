"""ONNX companions of checkpoints: Full-Meta's network on ONNX Runtime without importing torch.

A ``.pt`` checkpoint needs torch (~1.5 s to import) and an export (~0.5 s) before the first frame. Its
companion ``<name>.onnx`` holds the exported network plus, in the model's metadata, the checkpoint's
SHA-256 and what inference needs (variant, patch size, trained effects, training info). The bundled
weights ship their companion; for other checkpoints the first load exports one into the user's cache
(``$XDG_CACHE_HOME/noise_monitor/onnx``), so later loads start as fast.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

META_KEY = "noise_monitor"


def sha256_of(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "noise_monitor" / "onnx"


def companions(pt_path: Path, sha: str) -> list[Path]:
    """Where a checkpoint's companion may be: beside it, then in the cache."""
    return [pt_path.with_suffix(".onnx"), cache_dir() / f"{sha}.onnx"]


def session(data: bytes, threads: int) -> Any:
    """An ONNX Runtime CPU session of serialized model bytes."""
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.log_severity_level = 3
    return ort.InferenceSession(data, opts, providers=["CPUExecutionProvider"])


def find(pt_path: Path, threads: int) -> tuple[Any, dict[str, Any]] | None:
    """(session, metadata) of a companion matching the checkpoint's bytes, else None."""
    sha = sha256_of(pt_path)
    for path in companions(pt_path, sha):
        if not path.is_file():
            continue
        try:
            sess = session(path.read_bytes(), threads)
            meta = json.loads(sess.get_modelmeta().custom_metadata_map[META_KEY])
        except Exception:  # a damaged or foreign cache file is ignored (the .pt is the truth)
            continue
        if meta.get("source_sha256") == sha:
            return sess, meta
    return None


def with_metadata(model_bytes: bytes, meta: dict[str, Any]) -> bytes:
    """The exported model with ``meta`` stored under :data:`META_KEY`."""
    import onnx

    model = onnx.load_from_string(model_bytes)
    del model.metadata_props[:]
    entry = model.metadata_props.add()
    entry.key, entry.value = META_KEY, json.dumps(meta, sort_keys=True)
    return model.SerializeToString()


def write(path: Path, data: bytes) -> bool:
    """Write a companion atomically; False (and nothing written) where the folder is not writable."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, path)
        return True
    except OSError:
        return False


def write_beside(pt_path: Path) -> Path:
    """Export a Full-Meta checkpoint's companion next to it (``<name>.onnx``; do this when shipping weights)."""
    from .inference import FullMetaEstimator, load

    est = load("full_meta", device="cpu", weights=pt_path, backend="torch")
    if not isinstance(est, FullMetaEstimator):
        raise ValueError(f"{pt_path} is not a full_meta checkpoint")
    out = pt_path.with_suffix(".onnx")
    if not write(out, est.companion(sha256_of(pt_path))):
        raise OSError(f"cannot write {out}")
    return out


if __name__ == "__main__":  # python -m noise_monitor.estimator.onnx_weights WEIGHTS.pt
    import sys

    print(write_beside(Path(sys.argv[1])))
