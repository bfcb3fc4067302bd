"""Guarded YAML and JSON loading: every problem with a file is a :class:`FormatError`, nothing else.

``yaml.safe_load`` alone lets a hand-made or third-party file escape as ``UnicodeDecodeError`` (not UTF-8),
``RecursionError`` (5000 ``[``), ``ValueError`` (``2001-13-45`` read as a date), or take seconds to scan a
deeply nested flow (PyYAML's scanner is quadratic in the nesting depth); an alias bomb (``&a [*b, *b, …]``)
expands to billions of entries in whoever walks the result. These loaders refuse all of that up front.

Example:
    >>> data = load_yaml(clip / "camera.yaml", fix="re-run `rally3d calibrate CLIP`")
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from .csvtable import read_text
from .errors import FormatError

MAX_DEPTH = 64
"""Deepest nesting of lists/mappings accepted (the project's files need fewer than 6 levels)."""
MAX_NODES = 2_000_000
"""Most values a file may expand to (YAML aliases repeat a value without copying it)."""


YAML_FIX = "check indentation and 'key: value' syntax"


def load_yaml(path: str | Path, *, fix: str = YAML_FIX) -> Any:
    """Read and parse a YAML file (UTF-8); :class:`FormatError` naming the file, line and ``fix`` if not."""
    path = Path(path)
    return parse_yaml(path, read_text(path), fix=fix)


def parse_yaml(path: Path, text: str, *, fix: str = YAML_FIX) -> Any:
    """Parse YAML ``text`` read from ``path`` (named in errors)."""
    _check_flow_depth(path, text)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        problem = getattr(err, "problem", None) or str(err)
        raise FormatError(path, f"not valid YAML ({problem})", line=mark.line + 1 if mark else None,
                          fix=fix) from None
    except RecursionError:
        raise _too_deep(path) from None
    except Exception as err:  # e.g. a date that does not exist (2001-13-45) fails in its constructor
        raise FormatError(path, f"not valid YAML ({type(err).__name__}: {err})", fix=fix) from None
    check_size(path, data)
    return data


def yaml_key_lines(path: Path, text: str) -> dict[Any, int]:
    """1-based line of each top-level key of YAML ``text`` ({} when it is not a mapping)."""
    _check_flow_depth(path, text)
    try:
        node = yaml.compose(text)
    except RecursionError:
        raise _too_deep(path) from None
    except yaml.YAMLError:
        return {}
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {key.value: key.start_mark.line + 1 for key, _ in node.value if isinstance(key, yaml.ScalarNode)}


def load_json(path: str | Path, *, fix: str = "") -> Any:
    """Read and parse a JSON file (UTF-8); :class:`FormatError` naming the file, line and ``fix`` if not."""
    path = Path(path)
    text = read_text(path)
    _check_flow_depth(path, text)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise FormatError(path, f"not valid JSON ({err.msg})", line=err.lineno, fix=fix) from None
    except RecursionError:
        raise _too_deep(path) from None
    except ValueError as err:  # e.g. an integer with more digits than Python converts
        raise FormatError(path, f"not valid JSON ({err})", fix=fix) from None
    return data


def _too_deep(path: Path) -> FormatError:
    return FormatError(path, f"nested deeper than {MAX_DEPTH} levels",
                       fix="this is not a rally3d file; check its contents")


def _check_flow_depth(path: Path, text: str) -> None:
    """Refuse ``[``/``{`` nested deeper than :data:`MAX_DEPTH` (outside quotes and comments), in one pass."""
    depth, quote, line = 0, "", 1
    prev = "\n"
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
        if quote:
            if c == "\\" and quote == '"':
                i += 1
            elif c == quote:
                quote = ""
        elif c == "#" and prev in " \t\n":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'" and (prev in " \t\n[{,:" or depth):
            quote = c
        elif c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise FormatError(path, f"nested deeper than {MAX_DEPTH} levels", line=line,
                                  fix="this is not a rally3d file; check its contents")
        elif c in "]}":
            depth = max(depth - 1, 0)
        prev = c
        i += 1


def check_size(path: Path, data: Any) -> None:
    """Refuse parsed data that expands to more than :data:`MAX_NODES` values (alias bombs)."""
    sizes: dict[int, int] = {}

    def size(obj: Any, depth: int) -> int:
        if depth > MAX_DEPTH:
            raise _too_deep(path)
        if not isinstance(obj, (list, dict)):
            return 1
        key = id(obj)
        if sizes.get(key) == 0:
            raise FormatError(path, "a value contains itself (a YAML alias to its own anchor)",
                              fix="this is not a rally3d file; check its contents")
        if key not in sizes:
            sizes[key] = 0  # in progress: meeting it again below is a cycle
            items = obj.values() if isinstance(obj, dict) else obj
            total = 1
            for item in items:
                total += size(item, depth + 1)
                if total > MAX_NODES:
                    break
            sizes[key] = total
        if sizes[key] > MAX_NODES:
            raise FormatError(path, f"expands to more than {MAX_NODES:,} values (YAML aliases?)",
                              fix="this is not a rally3d file; check its contents")
        return sizes[key]

    total = size(data, 0)
    if total > MAX_NODES:
        raise FormatError(path, f"expands to more than {MAX_NODES:,} values (YAML aliases?)",
                          fix="this is not a rally3d file; check its contents")
