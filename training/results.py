"""Evaluation result files: every table row of a run as ``<stem>.json`` and ``<stem>.csv``.

One row is a flat mapping (model, checkpoint, data, split, ball input, table, class, metric columns); the
JSON file also holds the command and the config with its interpolations resolved (``split_seed: 1234``, not
``${seed}``; :func:`resolved`), so a result can be traced to what produced it.
The CSV has the union of the rows' columns in first-seen order (empty cells where a row lacks one).

Example:
    >>> write_results([{"model": "wasb", "class": "all", "f1": 0.9}], "runs/eval/x/results", config=cfg)
"""
from __future__ import annotations

import csv
import io
import json
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from inference.clipio import atomic_write_text


def _plain(v: Any) -> Any:
    if hasattr(v, "item") and callable(v.item):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    return str(v)


def resolved(node: Any) -> Any:
    """A plain copy (dicts, lists, values) of an OmegaConf config with every interpolation resolved; a value that
    cannot be resolved here (``${hydra:…}`` outside a Hydra run) is kept as written. Anything else is returned."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if not isinstance(node, (DictConfig, ListConfig)):
        return node
    try:
        return OmegaConf.to_container(node, resolve=True)
    except Exception:  # noqa: BLE001 - one value only Hydra's runtime can resolve: resolve the others one by one
        raw = OmegaConf.to_container(node, resolve=False)

    def one(key):
        try:
            return resolved(node[key])
        except Exception:  # noqa: BLE001 - as above, for this value
            return raw[key]

    keys = list(raw) if isinstance(raw, dict) else range(len(raw))
    values = {k: one(k) for k in keys}
    return values if isinstance(raw, dict) else list(values.values())


def write_results(rows: Sequence[Mapping[str, Any]], stem: str | Path, config: Any = None,
                  command: Sequence[str] | None = None) -> tuple[Path, Path]:
    """Write ``stem.json`` and ``stem.csv`` atomically; returns their paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    rows = [{k: _plain(v) for k, v in r.items()} for r in rows]
    columns: list[str] = []
    for r in rows:
        columns += [k for k in r if k not in columns]
    blob = {"command": list(command if command is not None else sys.argv), "config": resolved(config), "rows": rows}
    json_path = atomic_write_text(stem.with_suffix(".json"), json.dumps(blob, indent=2, default=str) + "\n")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    csv_path = atomic_write_text(stem.with_suffix(".csv"), buf.getvalue())
    return Path(json_path), Path(csv_path)
