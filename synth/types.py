"""Data passed between the stages of the synthetic rally generator.

simulate (physics + rally planner) → :class:`Rally` → articulate players → render frames → write clip.
All positions are in the court frame (metres, z up; docs/formats.md); times in seconds from the
clip's first frame; frame ``i`` is exposed around ``t = i / fps``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.players.skeleton import COCO17, COCO17_BONES  # noqa: F401  (re-exported for the generator)


@dataclass
class Contact:
    """One contact of the ball, an event of events.csv.

    Attributes:
        t: time of the contact in seconds.
        event: fine-grained label (``ground``, ``wall_near``, ..., ``player_near``, ``player_far``).
        position: (3,) ball centre at the contact.
        plane: name of the court plane touched (None for a racket hit).
        player: index into :attr:`Rally.players` for a racket hit (None otherwise).
        in_rally: False for a contact outside the point (the server's bounces before the serve, the ball
            after the point is over): not an event of events.csv.
    """

    t: float
    event: str
    position: np.ndarray
    plane: str | None = None
    player: int | None = None
    in_rally: bool = True


@dataclass
class BallPath:
    """The ball in play, densely sampled (at least 10 samples per frame).

    Attributes:
        t: (N,) increasing times.
        pos: (N, 3) ball centre; vel: (N, 3) velocity; spin: (N, 3) angular velocity (rad/s).
        in_play: (N,) bool, False before the first hit and after the ball is dead/gone.
    """

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    spin: np.ndarray
    in_play: np.ndarray

    def sample(self, times: np.ndarray) -> np.ndarray:
        """(M,) times → (M, 3) positions by linear interpolation of the dense samples."""
        return np.stack([np.interp(times, self.t, self.pos[:, k]) for k in range(3)], axis=1)


@dataclass
class Swing:
    """A racket stroke of one player.

    Attributes:
        t_hit: time of ball contact.
        hit_point: (3,) ball centre at contact.
        kind: ``serve``, ``forehand``, ``backhand``, ``volley``, ``overhead`` or ``lob``.
    """

    t_hit: float
    hit_point: np.ndarray
    kind: str


@dataclass
class PlayerPlan:
    """Where one player is over the clip, as planned by the rally simulation.

    Attributes:
        player_id: stable id (0..P-1).
        team: ``near`` or ``far``.
        handed: ``right`` or ``left``.
        height: standing height in metres.
        t: (T,) times (one per frame); root: (T, 2) floor position of the pelvis; heading: (T,) yaw in
            radians (0 faces +y, i.e. away from the camera).
        swings: strokes in time order.
    """

    player_id: int
    team: str
    handed: str
    height: float
    t: np.ndarray
    root: np.ndarray
    heading: np.ndarray
    swings: list[Swing] = field(default_factory=list)


@dataclass
class InactiveBall:
    """A ball lying still on court between frames ``first`` and ``last`` (inclusive)."""

    ball_no: int
    position: np.ndarray
    first: int
    last: int


@dataclass
class Rally:
    """A simulated rally: what the renderer draws and what the ground-truth files record.

    Attributes:
        sport: ``padel`` or ``tennis``; fps; n_frames.
        ball: the ball in play; contacts: every contact in time order (racket hits included).
        players: the players' plans; inactive_balls: stationary balls on court.
        outcome: how the rally ended (``winner``, ``error_net``, ``error_out``, ...).
        t_serve, t_dead: the serve's racket contact and the moment the ball is dead (s).
    """

    sport: str
    fps: float
    n_frames: int
    ball: BallPath
    contacts: list[Contact]
    players: list[PlayerPlan]
    inactive_balls: list[InactiveBall] = field(default_factory=list)
    outcome: str = ""
    t_serve: float | None = None
    t_dead: float | None = None

    @property
    def frame_times(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.fps

    def event_frames(self) -> list[tuple[int, str]]:
        """(frame, label) of every contact of the point: the frame nearest to the contact time."""
        return [(int(round(c.t * self.fps)), c.event) for c in self.contacts if c.in_rally]

    def rally_frames(self) -> tuple[int, int] | None:
        """(serve frame, dead-ball frame) of the point, clipped to the clip; None when unknown."""
        if self.t_serve is None or self.t_dead is None:
            return None
        last = self.n_frames - 1
        return (min(int(round(self.t_serve * self.fps)), last), min(int(round(self.t_dead * self.fps)), last))
