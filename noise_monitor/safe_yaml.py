"""The one YAML loader of the package: safe (no object tags), bounded, one-line errors.

Every YAML document noise_monitor parses (camera profiles, node parameter files, a rosbag2 bag's
``metadata.yaml``) goes through :func:`load`. Beyond ``yaml.safe_load`` it rejects documents whose
aliases expand to more than :data:`MAX_EXPANDED_NODES` nodes ("billion laughs": a few hundred bytes that
become gigabytes once anything walks or prints the result) and files larger than :data:`MAX_BYTES`, and
it reports syntax errors in one line. Numbers with an exponent but no dot (``1e-3``) are floats, as in ROS 2.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

#: Nodes a document may hold after alias expansion (the bundled files have a few hundred).
MAX_EXPANDED_NODES = 100_000
#: Largest YAML file read (bytes).
MAX_BYTES = 4 * 1024 * 1024



class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """The safe loader, reading ``1e-3`` and ``1e400`` as floats as ROS 2 (YAML 1.2) does, not as text."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))


class YamlError(ValueError):
    """A YAML document that is malformed, too large or an alias bomb; the message is one line."""


def _expanded_size(root: yaml.Node, limit: int) -> int:
    """Nodes of the document with every alias expanded, counted without expanding (memoised per node);
    stops counting once past ``limit``."""
    sizes: dict[int, int] = {}
    # iterative post-order walk: deep nesting must not hit the recursion limit
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        children: list[yaml.Node] = []
        if isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        elif isinstance(node, yaml.MappingNode):
            children = [n for kv in node.value for n in kv]
        if not done:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
            continue
        total = 1 + sum(sizes.get(id(c), 0) for c in children)
        sizes[id(node)] = min(total, limit + 1)
    return sizes[id(root)]


def _one_line(exc: yaml.YAMLError) -> str:
    problem = getattr(exc, "problem", None) or getattr(exc, "context", None) or type(exc).__name__
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{where}"


def loads(text: str, source: str = "YAML") -> Any:
    """Parse one YAML document (plain data only); YamlError names ``source`` and the problem."""
    if len(text) > MAX_BYTES:
        raise YamlError(f"{source}: YAML document of {len(text)} characters is larger than {MAX_BYTES}")
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        if _expanded_size(node, MAX_EXPANDED_NODES) > MAX_EXPANDED_NODES:
            raise YamlError(f"{source}: YAML aliases expand to more than {MAX_EXPANDED_NODES} nodes "
                            "(an alias bomb?); refused")
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise YamlError(f"{source}: not valid YAML ({_one_line(exc)})") from None
    except RecursionError:
        raise YamlError(f"{source}: YAML nested too deeply") from None
    finally:
        loader.dispose()


def load(path: str | Path) -> Any:
    """Parse a YAML file (see :func:`loads`); a file above :data:`MAX_BYTES` is refused unread."""
    p = Path(path)
    size = p.stat().st_size
    if size > MAX_BYTES:
        raise YamlError(f"{p}: YAML file of {size} bytes is larger than {MAX_BYTES}")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise YamlError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return loads(text, str(p))
