"""Class sets of the hit-event models: the coarse classes a model predicts and the mapping from the
fine-grained labels of ``events.csv`` (docs/formats.md) onto them.

A class set is data (``conf/events/<name>.yaml``) and travels inside every exported model, so the
runtime never needs the config folder.

Example:
    >>> cs = ClassSet.load("padel6")
    >>> cs.classes
    ('none', 'wall_near', 'ground_or_other_wall', 'player_near', 'player_far', 'net')
    >>> cs.encode_label("wall_left")
    2
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from inference.clipio import EVENT_LABELS, HitEvents
from inference.court import CONF_DIR

log = logging.getLogger(__name__)

UNMAPPED_POLICIES = ("error", "warn")


class UnmappedLabelError(ValueError):
    """The data holds a fine-grained label that the class set does not map to a class."""


@dataclass(frozen=True)
class DecodeRules:
    """Sport rules the decoder enforces.

    Attributes:
        hits: the two racket-hit classes (near team, far team); consecutive hits alternate.
        max_between_hits: most non-hit events between two consecutive hits.
        requires_last_hit: class → the hit class that must be the latest hit before it.
    """

    hits: tuple[str, str] = ("player_near", "player_far")
    max_between_hits: int = 4
    requires_last_hit: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ClassSet:
    """Coarse classes of an event model.

    Attributes:
        name: e.g. ``padel6``; sport: ``padel`` or ``tennis``.
        classes: class names, index 0 is ``none``.
        map: fine label → class name.
        default_fine: class → the fine label written when nothing better is known (classes standing for
            one fine label need no entry).
        resolve_with_camera: class → fine labels among which a camera ray/plane test picks.
        mirror_pairs: fine labels swapped by a horizontal mirror of the image.
        rules: decoding rules.
    """

    name: str
    sport: str
    classes: tuple[str, ...]
    map: dict[str, str]
    default_fine: dict[str, str] = field(default_factory=dict)
    resolve_with_camera: dict[str, tuple[str, ...]] = field(default_factory=dict)
    mirror_pairs: tuple[tuple[str, str], ...] = ()
    rules: DecodeRules = DecodeRules()

    def __post_init__(self) -> None:
        if not self.classes or self.classes[0] != "none":
            raise ValueError(f"class set {self.name}: the first class must be 'none', got {self.classes[:1]}")
        if len(set(self.classes)) != len(self.classes):
            raise ValueError(f"class set {self.name}: duplicate classes in {self.classes}")
        bad = sorted(set(self.map) - set(EVENT_LABELS))
        if bad:
            raise ValueError(f"class set {self.name}: unknown fine labels {bad}; valid: {EVENT_LABELS}")
        bad = sorted(set(self.map.values()) - set(self.classes[1:]))
        if bad:
            raise ValueError(f"class set {self.name}: map targets {bad} are not classes {self.classes[1:]}")
        for hit in self.rules.hits:
            if hit not in self.classes:
                raise ValueError(f"class set {self.name}: rule hit class {hit!r} is not a class")

    # ------------------------------------------------------------------------------------ loading
    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ClassSet:
        rules = d.get("rules") or {}
        return cls(
            name=str(d["name"]), sport=str(d.get("sport", "")), classes=tuple(d["classes"]), map=dict(d["map"]),
            default_fine=dict(d.get("default_fine") or {}),
            resolve_with_camera={k: tuple(v) for k, v in (d.get("resolve_with_camera") or {}).items()},
            mirror_pairs=tuple(tuple(p) for p in (d.get("mirror_pairs") or [])),
            rules=DecodeRules(hits=tuple(rules.get("hits", ("player_near", "player_far"))),
                              max_between_hits=int(rules.get("max_between_hits", 4)),
                              requires_last_hit=dict(rules.get("requires_last_hit") or {})),
        )

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "sport": self.sport, "classes": list(self.classes), "map": dict(self.map),
                "default_fine": dict(self.default_fine),
                "resolve_with_camera": {k: list(v) for k, v in self.resolve_with_camera.items()},
                "mirror_pairs": [list(p) for p in self.mirror_pairs],
                "rules": {"hits": list(self.rules.hits), "max_between_hits": self.rules.max_between_hits,
                          "requires_last_hit": dict(self.rules.requires_last_hit)}}

    @classmethod
    def load(cls, name_or_path: str | Path | dict) -> ClassSet:
        """A class set by name (``conf/events/<name>.yaml``), YAML path, or dict (e.g. a Hydra node)."""
        if isinstance(name_or_path, ClassSet):
            return name_or_path
        if not isinstance(name_or_path, (str, Path)):
            return cls.from_dict(dict(name_or_path))
        p = Path(name_or_path)
        if p.suffix not in (".yaml", ".yml"):
            p = CONF_DIR / "events" / f"{name_or_path}.yaml"
        if not p.is_file():
            known = sorted(f.stem for f in (CONF_DIR / "events").glob("*.yaml"))
            raise FileNotFoundError(f"no class set {name_or_path!r} (looked for {p}); known: {known}")
        return cls.from_dict(yaml.safe_load(p.read_text()))

    # ------------------------------------------------------------------------------------ encoding
    @property
    def n(self) -> int:
        return len(self.classes)

    def index(self, name: str) -> int:
        return self.classes.index(name)

    def encode_label(self, fine: str) -> int | None:
        """Class index of a fine label, or None when the class set does not cover it."""
        c = self.map.get(fine)
        return None if c is None else self.classes.index(c)

    def encode(self, events: HitEvents, n_frames: int, *, on_unmapped: str = "error",
               where: str = "") -> np.ndarray:
        """``(n_frames,) int64`` class per frame (0 = none) from fine-grained events.

        Args:
            on_unmapped: ``error`` raises :class:`UnmappedLabelError` for a label the set does not map;
                ``warn`` warns once per label and treats those events as ``none``.
            where: names the data in messages (a clip path).
        """
        if on_unmapped not in UNMAPPED_POLICIES:
            raise ValueError(f"on_unmapped must be one of {UNMAPPED_POLICIES}, got {on_unmapped!r}")
        y = np.zeros(n_frames, np.int64)
        missing: dict[str, int] = {}
        for f, e in zip(events.frame, events.event):
            c = self.encode_label(str(e))
            if c is None:
                missing[str(e)] = missing.get(str(e), 0) + 1
                continue
            if f < n_frames:
                y[f] = c
        if missing:
            msg = (f"class set {self.name} does not cover the label(s) {missing} (label: count) in "
                   f"{where or 'the data'}; add them to `map` of conf/events/{self.name}.yaml or use a class set "
                   "that covers them")
            if on_unmapped == "error":
                raise UnmappedLabelError(msg + " (or set on_unmapped=warn to treat them as none)")
            warnings.warn(msg + "; treated as none", stacklevel=2)
        return y

    def mirror_permutation(self) -> np.ndarray:
        """``(C,)`` class index permutation of a horizontal mirror (identity when no pair splits classes)."""
        perm = np.arange(self.n)
        for a, b in self.mirror_pairs:
            ca, cb = self.encode_label(a), self.encode_label(b)
            if ca is not None and cb is not None and ca != cb:
                perm[ca], perm[cb] = cb, ca
        return perm

    def fine_label(self, cls_name: str) -> str:
        """The fine label written for a class when no camera resolves it."""
        if cls_name in self.default_fine:
            return self.default_fine[cls_name]
        fines = [f for f, c in self.map.items() if c == cls_name]
        if cls_name in EVENT_LABELS:
            return cls_name
        if not fines:
            raise ValueError(f"class {cls_name!r} of {self.name} maps from no fine label")
        return fines[0]
