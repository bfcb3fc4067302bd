"""``players.csv``: player tracks with COCO-17 keypoints, one row per player per frame.

Columns::

    frame,player_id,team,score,x1,y1,x2,y2,court_x_m,court_y_m,
    <joint>_x,<joint>_y,<joint>_s   for each COCO-17 joint (normalised image coords, score 0..1)
    [<joint>_x_m,<joint>_y_m,<joint>_z_m  for each joint: 3D in the court frame, ground truth only]

Image coordinates are normalised (``u = x_px / width``); unlike ball.csv they may lie outside [0, 1]
(a joint or box can leave the image) but must be finite where given. Empty = unknown (NaN).
``team`` is ``near``, ``far`` or empty.

A file from another tool (e.g. ``frame,track_id,team,x_m,y_m``) is read for what it has: only ``frame``
is required, :data:`ALIASES` map common other names onto ours, missing columns are unknown (NaN) and a
team other than ``near``/``far`` is unknown; one warning lists what was missing or ignored.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inference.players.skeleton import COCO17

from .csvtable import CsvTable, duplicated, format_floats, format_ints, write_csv
from .tables import ArraysEqualMixin, as_matrix, as_strings, as_vector, check_frames

TEAMS = ("near", "far", "")
BASE_COLUMNS = ("frame", "player_id", "team", "score", "x1", "y1", "x2", "y2", "court_x_m", "court_y_m")
KP_COLUMNS = tuple(f"{j}_{c}" for j in COCO17 for c in ("x", "y", "s"))
KP3D_COLUMNS = tuple(f"{j}_{c}_m" for j in COCO17 for c in ("x", "y", "z"))
J = len(COCO17)
#: Other tools' names for our columns (matched case-insensitively) in a players.csv of another layout.
ALIASES = {"player_id": ("track_id", "id", "player"), "team": ("side",),
           "court_x_m": ("x_m", "court_x"), "court_y_m": ("y_m", "court_y")}


@dataclass(eq=False)
class PlayerTracks(ArraysEqualMixin):
    """Players of one clip.

    Attributes:
        frame: (N,) int64, sorted; (frame, player_id) unique.
        player_id: (N,) int64 >= 0, the track identity.
        team: (N,) ``near``, ``far`` or ``""``.
        score: (N,) detection score (NaN unknown).
        bbox: (N, 4) normalised ``x1, y1, x2, y2`` (NaN unknown).
        keypoints: (N, 17, 3) normalised ``x, y`` and score per COCO-17 joint (NaN where missing).
        court_xy: (N, 2) the player's floor position in court metres (NaN unknown).
        joints_3d: (N, 17, 3) court-frame joints in metres, ground truth only (all NaN otherwise).
    """

    frame: np.ndarray
    player_id: np.ndarray
    team: np.ndarray
    score: np.ndarray
    bbox: np.ndarray
    keypoints: np.ndarray
    court_xy: np.ndarray
    joints_3d: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.frame = as_vector(self.frame, "frame", np.int64)
        n = len(self.frame)
        self.player_id = as_vector(self.player_id, "player_id", np.int64, n)
        self.team = as_strings(list(self.team), "team", n)
        self.score = as_vector(self.score, "score", np.float64, n)
        self.bbox = as_matrix(self.bbox, "bbox", n, 4)
        self.keypoints = np.asarray(self.keypoints, dtype=np.float64).reshape(n, J, 3)
        self.court_xy = as_matrix(self.court_xy, "court_xy", n, 2)
        if self.joints_3d is None:
            self.joints_3d = np.full((n, J, 3), np.nan)
        self.joints_3d = np.asarray(self.joints_3d, dtype=np.float64).reshape(n, J, 3)
        check_frames(self.frame, strict=False)
        if n and self.player_id.min() < 0:
            raise ValueError("player_id must be >= 0")
        bad = sorted(set(self.team.tolist()) - set(TEAMS))
        if bad:
            raise ValueError(f"team has unknown values {bad}; valid: near, far or empty")
        for name in ("score", "bbox", "keypoints", "court_xy", "joints_3d"):
            if np.isinf(getattr(self, name)).any():
                raise ValueError(f"{name} must not be infinite")
        if duplicated(np.stack([self.frame, self.player_id], axis=1)).any():
            raise ValueError("(frame, player_id) must be unique")

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> PlayerTracks:
        return cls(np.empty(0, np.int64), np.empty(0, np.int64), [], np.empty(0), np.empty((0, 4)),
                   np.empty((0, J, 3)), np.empty((0, 2)))

    @property
    def has_3d(self) -> bool:
        return bool(np.isfinite(self.joints_3d).any())

    def ids(self) -> list[int]:
        return sorted(set(self.player_id.tolist()))

    def of_player(self, player_id: int) -> PlayerTracks:
        """The rows of one player."""
        return self.rows(self.player_id == player_id)

    def rows(self, mask: np.ndarray) -> PlayerTracks:
        """The rows where ``mask`` ((N,) bool) is True."""
        m = np.asarray(mask, bool)
        return PlayerTracks(self.frame[m], self.player_id[m], self.team[m], self.score[m], self.bbox[m],
                            self.keypoints[m], self.court_xy[m], self.joints_3d[m])


def read_players_csv(path: str | Path, *, n_frames: int | None = None) -> PlayerTracks:
    """Read ``players.csv``; the 3D joint columns are optional.

    A file in another layout (any base or keypoint column missing) is read for what it has, with one
    warning (module docstring); only a missing ``frame`` column, a bad value in a column that is there, or
    a repeated (frame, player) is an error.
    """
    table = CsvTable.read(path, ("frame",), optional=BASE_COLUMNS + KP_COLUMNS + KP3D_COLUMNS)
    names = _column_names(table)
    foreign = any(c not in names for c in BASE_COLUMNS + KP_COLUMNS)
    frame = table.ints("frame")
    table.check_frames(frame, n_frames=n_frames, unique=False)
    n = len(table)
    notes: list[str] = []
    if "player_id" in names:
        pid = table.ints(names["player_id"])
        table.check(pid < 0, lambda i: f"negative player_id {pid[i]}", fix="number players 0, 1, 2, ...")
    else:  # one anonymous player per row of a frame
        pid = np.zeros(n, np.int64)
        for f in np.unique(frame):
            rows = np.flatnonzero(frame == f)
            pid[rows] = np.arange(len(rows))
    table.check(duplicated(np.stack([frame, pid], axis=1)),
                lambda i: f"duplicate (frame, player_id) = ({frame[i]}, {pid[i]})",
                fix="keep one row per player and frame")
    team = np.array(table.strings(names["team"]) if "team" in names else [""] * n, dtype=str).reshape(n)
    unknown = ~np.isin(team, TEAMS)
    if foreign and unknown.any():
        notes.append(f"team values {sorted(set(team[unknown].tolist()))[:5]} read as unknown (use near/far)")
        team = np.where(unknown, "", team)
    table.check(~np.isin(team, TEAMS), lambda i: f"unknown team {str(team[i])!r}", fix="use near, far or leave empty")

    def cols(wanted) -> np.ndarray:
        out = np.full((n, len(wanted)), np.nan)
        for k, c in enumerate(wanted):
            if c in names:
                out[:, k] = table.floats(names[c], allow_empty=True)
        return out

    score = cols(("score",))[:, 0]
    kp = cols(KP_COLUMNS).reshape(-1, J, 3)
    has3d = all(c in names for c in KP3D_COLUMNS)
    j3d = cols(KP3D_COLUMNS).reshape(-1, J, 3) if has3d else None
    if foreign:
        missing = [c for c in BASE_COLUMNS if c not in names]
        kp_missing = sum(c not in names for c in KP_COLUMNS)
        what = missing + ([f"{kp_missing} keypoint columns"] if kp_missing else [])
        notes.insert(0, f"another layout: read {', '.join(sorted(set(names.values()) - {'frame'}) or ['frame'])}"
                        f"; unknown (missing): {', '.join(what)}")
        warnings.warn(f"{path}: " + "; ".join(notes), stacklevel=2)
    order = np.lexsort((pid, frame))
    return PlayerTracks(frame[order], pid[order], team[order], score[order], cols(("x1", "y1", "x2", "y2"))[order],
                        kp[order], cols(("court_x_m", "court_y_m"))[order],
                        None if j3d is None else j3d[order])


def _column_names(table: CsvTable) -> dict[str, str]:
    """Our column name → the file's column holding it (exact names first, then :data:`ALIASES`)."""
    lower = {h.lower(): h for h in table.header}
    out = {c: c for c in BASE_COLUMNS + KP_COLUMNS + KP3D_COLUMNS if table.has(c)}
    for ours, others in ALIASES.items():
        if ours not in out:
            found = [lower[o] for o in (ours, *others) if o in lower]
            if found:
                out[ours] = found[0]
    return out


def write_players_csv(path: str | Path, players: PlayerTracks) -> Path:
    """Write ``players.csv`` atomically (3D joint columns only when any is known)."""
    order = np.lexsort((players.player_id, players.frame))
    p = players
    columns = [format_ints(p.frame[order]), format_ints(p.player_id[order]), p.team[order].tolist(),
               format_floats(p.score[order], 4)]
    columns += [format_floats(p.bbox[order, k], 7) for k in range(4)]
    columns += [format_floats(p.court_xy[order, k], 5) for k in range(2)]
    kp = p.keypoints[order].reshape(len(p), 3 * J)
    columns += [format_floats(kp[:, k], 7 if k % 3 < 2 else 4) for k in range(kp.shape[1])]
    header = list(BASE_COLUMNS + KP_COLUMNS)
    if p.has_3d:
        j3 = p.joints_3d[order].reshape(len(p), 3 * J)
        columns += [format_floats(j3[:, k], 5) for k in range(j3.shape[1])]
        header += list(KP3D_COLUMNS)
    return write_csv(path, header, columns)
