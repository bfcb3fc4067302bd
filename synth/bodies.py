"""Articulated players: a :class:`PlayerPlan` → COCO-17 joints, a racket, and capsule body volumes.

The model is kinematic, not dynamic: a pelvis that follows the planned root, a torso that twists and
leans, two-bone inverse kinematics for the arms and legs, a gait (leg swing growing with speed) when
the root moves, a ready stance when it does not, and for each planned swing a keyframed stroke
(ready → backswing → contact → follow-through → ready) whose contact keyframe is solved so that the
racket head centre is exactly at ``Swing.hit_point`` at ``Swing.t_hit``. When the hit point is out of
reach the whole body lunges, crouches or jumps towards it for a moment around the hit.

Conventions: court frame (metres, z up). ``heading`` 0 faces +y, positive angles turn counter-clockwise
seen from above, so the forward vector is ``(-sin h, cos h, 0)`` and the right vector ``(cos h, sin h, 0)``.
Segment lengths are fractions of the standing height (Drillis & Contini's anthropometric proportions, as
tabulated in Winter, *Biomechanics and Motor Control of Human Movement*).

Example:
    >>> plan = PlayerPlan(0, "near", "right", 1.8, t=np.arange(30) / 30, root=np.tile([5.0, 2.0], (30, 1)),
    ...                   heading=np.zeros(30))
    >>> pose = articulate(plan, fps=30, rng=np.random.default_rng(0))
    >>> pose.joints.shape, pose.racket.shape, len(capsules(pose, 0)) == len(CAPSULE_NAMES)
    ((30, 17, 3), (30, 2, 3), True)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.types import PlayerPlan, Swing

UP = np.array([0.0, 0.0, 1.0])
MIN_WRIST = 0.4  # closest the wrist comes to its shoulder, as a fraction of the arm's length


@dataclass(frozen=True)
class BodyProportions:
    """Segment lengths and capsule radii as fractions of the standing height."""

    hip_height: float = 0.530  # hip joint above the floor, standing
    spine: float = 0.288  # hip line → shoulder line (0.818 - 0.530)
    neck: float = 0.117  # shoulder line → head centre (ear level, 0.935)
    shoulder_half: float = 0.110  # half the distance between the shoulder joints
    hip_half: float = 0.050  # half the distance between the hip joints
    upper_arm: float = 0.186
    forearm: float = 0.146
    hand: float = 0.060  # wrist → middle of the grip
    thigh: float = 0.245
    shank: float = 0.246
    ankle_height: float = 0.039
    foot: float = 0.152
    head_radius: float = 0.044
    head_half: float = 0.020  # half length of the head capsule's axis


BODY = BodyProportions()


@dataclass(frozen=True)
class RacketSpec:
    """A racket: overall length, head centre and grip measured from the handle end, head semi-axes (m)."""

    length: float
    head_centre: float
    grip: float
    head_semi_axes: tuple[float, float]  # along the racket, across it
    see_through: bool  # strung (tennis) rather than a solid perforated face (padel)


RACKETS = {
    "padel": RacketSpec(0.455, head_centre=0.31, grip=0.07, head_semi_axes=(0.15, 0.13), see_through=False),
    "tennis": RacketSpec(0.685, head_centre=0.515, grip=0.08, head_semi_axes=(0.17, 0.13), see_through=True),
}


@dataclass
class PlayerPose:
    """An articulated player over a clip, one sample per frame of its plan.

    Attributes:
        player_id, team, handed, height: copied from the plan.
        t: (T,) times.
        joints: (T, 17, 3) COCO-17 joints (types.COCO17 order), metres, court frame.
        racket: (T, 2, 3) handle end and head centre.
        racket_normal: (T, 3) unit normal of the racket face.
        heading: (T,) yaw of the feet/hips (radians, see the module docstring).
        build: girth factor applied to the capsule radii (1 = average).
        racket_spec: the racket's dimensions.
    """

    player_id: int
    team: str
    handed: str
    height: float
    t: np.ndarray
    joints: np.ndarray
    racket: np.ndarray
    racket_normal: np.ndarray
    heading: np.ndarray
    build: float = 1.0
    racket_spec: RacketSpec = RACKETS["padel"]

    @property
    def n_frames(self) -> int:
        return len(self.t)


# ------------------------------------------------------------------------------------------------------
# Capsule body volumes
# ------------------------------------------------------------------------------------------------------
#: Names of the capsules returned by :func:`capsules`, in order.
CAPSULE_NAMES = (
    "head", "hair", "neck", "torso_left", "torso_right", "chest", "pelvis",
    "upper_arm_left", "sleeve_left", "forearm_left", "hand_left",
    "upper_arm_right", "sleeve_right", "forearm_right", "hand_right",
    "thigh_left", "shorts_left", "shin_left", "foot_left",
    "thigh_right", "shorts_right", "shin_right", "foot_right",
)
#: What each capsule is made of (the renderer colours by it), same order as :data:`CAPSULE_NAMES`.
CAPSULE_MATERIALS = (
    "skin", "hair", "skin", "shirt", "shirt", "shirt", "shorts",
    "skin", "shirt", "skin", "skin",
    "skin", "shirt", "skin", "skin",
    "skin", "shorts", "skin", "shoes",
    "skin", "shorts", "skin", "shoes",
)
# capsule radii, fractions of the height (multiplied by PlayerPose.build)
_RADIUS = {
    "head": 0.044, "hair": 0.047, "neck": 0.030, "torso": 0.056, "pelvis": 0.052,
    "upper_arm": 0.024, "sleeve": 0.029, "forearm": 0.019, "hand": 0.020,
    "thigh": 0.038, "shorts": 0.043, "shin": 0.027, "foot": 0.021,
}


def _unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    """Normalise (..., 3) vectors; near-zero ones become ``fallback`` (default: up)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    fb = UP if fallback is None else fallback
    return np.where(n > 1e-9, v / np.maximum(n, 1e-12), fb)


def capsules(pose: PlayerPose, frame: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The body volumes of one frame: ``[(a (3,), b (3,), radius), ...]`` in :data:`CAPSULE_NAMES` order.

    A capsule is the set of points within ``radius`` of the segment ``a``-``b``.
    """
    j = pose.joints[frame]
    H, g = pose.height, pose.height * pose.build
    head_c = 0.5 * (j[3] + j[4])
    mid_sh = 0.5 * (j[5] + j[6])
    head_up = _unit(head_c - mid_sh)
    face = _unit(j[0] - head_c - ((j[0] - head_c) @ head_up) * head_up)
    lateral = _unit(j[6] - j[5])
    fwd = np.array([-np.sin(pose.heading[frame]), np.cos(pose.heading[frame]), 0.0])
    racket_dir = _unit(pose.racket[frame, 1] - pose.racket[frame, 0])
    racket_wrist = 10 if pose.handed == "right" else 9

    def arm(sh: int, el: int, wr: int) -> list:
        hand_dir = racket_dir if wr == racket_wrist else _unit(j[wr] - j[el])
        return [
            (j[sh], j[el], _RADIUS["upper_arm"] * g),
            (j[sh], j[sh] + 0.45 * (j[el] - j[sh]), _RADIUS["sleeve"] * g),
            (j[el], j[wr], _RADIUS["forearm"] * g),
            (j[wr], j[wr] + BODY.hand * H * hand_dir, _RADIUS["hand"] * g),
        ]

    def leg(hip: int, knee: int, ankle: int) -> list:
        return [
            (j[hip], j[knee], _RADIUS["thigh"] * g),
            (j[hip], j[hip] + 0.5 * (j[knee] - j[hip]), _RADIUS["shorts"] * g),
            (j[knee], j[ankle], _RADIUS["shin"] * g),
            (j[ankle] - 0.02 * H * fwd - 0.012 * H * UP, j[ankle] + 0.10 * H * fwd - 0.016 * H * UP,
             _RADIUS["foot"] * g),
        ]

    waist = 0.06 * H * UP
    inset = (BODY.shoulder_half - BODY.hip_half) * H * lateral  # torso sides run straight up from the hips
    caps = [
        (head_c - BODY.head_half * H * head_up, head_c + BODY.head_half * H * head_up, _RADIUS["head"] * g),
        (head_c + 0.010 * H * head_up - 0.012 * H * face, head_c + 0.024 * H * head_up - 0.008 * H * face,
         _RADIUS["hair"] * g),
        (mid_sh, head_c - 0.03 * H * head_up, _RADIUS["neck"] * g),
        (j[11] + waist, j[5] + inset - 0.02 * H * head_up, _RADIUS["torso"] * g),
        (j[12] + waist, j[6] - inset - 0.02 * H * head_up, _RADIUS["torso"] * g),
        (0.5 * (j[11] + j[12]) + waist, mid_sh - 0.03 * H * head_up, _RADIUS["torso"] * g),
        (j[11], j[12], _RADIUS["pelvis"] * g),
        *arm(5, 7, 9),
        *arm(6, 8, 10),
        *leg(11, 13, 15),
        *leg(12, 14, 16),
    ]
    return [(np.asarray(a, float), np.asarray(b, float), float(r)) for a, b, r in caps]


# ------------------------------------------------------------------------------------------------------
# Strokes
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Stroke:
    """Keyframes of one stroke for a right-hander (x right, y forward, z up, in the heading frame; wrist
    positions in heights from the pelvis centre of an upright, untwisted body, applied relative to the
    shoulders). ``dir_*`` is the racket direction (handle → head), ``off_*`` the
    other wrist, ``twist_*`` the shoulder yaw relative to the heading (radians). Times in seconds relative
    to the contact: the stroke leaves the ready pose ``start`` before it, is fully pulled back ``back``
    before it, reaches the follow-through ``follow`` after it and is back in the ready pose ``end`` after it.
    ``dir_c`` is the preferred racket direction at contact (it is bent towards the hit point to reach it).
    """

    start: float
    back: float
    follow: float
    end: float
    wrist_b: tuple
    dir_b: tuple
    off_b: tuple
    twist_b: float
    dir_c: tuple
    off_c: tuple
    twist_c: float
    wrist_f: tuple
    dir_f: tuple
    off_f: tuple
    twist_f: float
    overhead: bool = False  # arched back at contact instead of a forward lean


_READY_WRIST = (0.08, 0.20, 0.04)
_READY_DIR = (-0.2, 0.5, 0.85)
_READY_OFF = (-0.06, 0.22, 0.08)

_OVERHEAD = _Stroke(
    start=0.9, back=0.32, follow=0.25, end=0.7,
    wrist_b=(0.14, -0.10, 0.42), dir_b=(0.3, -0.7, -0.6), off_b=(-0.05, 0.25, 0.55), twist_b=-1.0,
    dir_c=(0.15, 0.3, 0.95), off_c=(-0.12, 0.12, 0.0), twist_c=-0.1,
    wrist_f=(-0.16, 0.14, -0.02), dir_f=(-0.6, 0.5, -0.6), off_f=(-0.12, 0.10, 0.0), twist_f=0.6,
    overhead=True,
)
_VOLLEY_FH = _Stroke(
    start=0.35, back=0.15, follow=0.15, end=0.4,
    wrist_b=(0.20, 0.05, 0.20), dir_b=(0.4, -0.1, 0.9), off_b=(-0.08, 0.22, 0.14), twist_b=-0.35,
    dir_c=(0.6, 0.45, 0.55), off_c=(-0.12, 0.20, 0.10), twist_c=-0.05,
    wrist_f=(0.10, 0.25, 0.08), dir_f=(0.45, 0.6, 0.3), off_f=(-0.10, 0.20, 0.10), twist_f=0.2,
)
STROKES: dict[str, _Stroke] = {
    "forehand": _Stroke(
        start=0.6, back=0.28, follow=0.22, end=0.6,
        wrist_b=(0.26, -0.16, 0.12), dir_b=(0.25, -0.55, 0.8), off_b=(0.05, 0.30, 0.15), twist_b=-1.0,
        dir_c=(0.85, 0.35, 0.15), off_c=(-0.18, 0.12, 0.05), twist_c=-0.1,
        wrist_f=(-0.16, 0.10, 0.24), dir_f=(-0.5, -0.45, 0.75), off_f=(-0.12, 0.14, 0.12), twist_f=0.7,
    ),
    "backhand": _Stroke(
        start=0.6, back=0.28, follow=0.22, end=0.6,
        wrist_b=(-0.20, -0.10, 0.10), dir_b=(-0.3, -0.6, 0.75), off_b=(-0.14, 0.02, 0.10), twist_b=1.1,
        dir_c=(-0.85, 0.35, 0.15), off_c=(0.16, -0.08, 0.02), twist_c=0.2,
        wrist_f=(0.22, 0.10, 0.26), dir_f=(0.45, -0.2, 0.85), off_f=(0.18, -0.02, 0.06), twist_f=-0.45,
    ),
    "volley_fh": _VOLLEY_FH,
    "volley_bh": _Stroke(
        start=0.35, back=0.15, follow=0.15, end=0.4,
        wrist_b=(-0.16, 0.05, 0.20), dir_b=(-0.4, -0.1, 0.9), off_b=(-0.10, 0.20, 0.14), twist_b=0.4,
        dir_c=(-0.6, 0.45, 0.55), off_c=(0.05, 0.10, 0.05), twist_c=0.1,
        wrist_f=(-0.05, 0.25, 0.08), dir_f=(-0.45, 0.6, 0.3), off_f=(0.05, 0.15, 0.05), twist_f=-0.15,
    ),
    "overhead": _OVERHEAD,
    "serve_over": _Stroke(**{**_OVERHEAD.__dict__, "start": 1.1, "back": 0.35}),
    "lob": _Stroke(
        start=0.6, back=0.28, follow=0.25, end=0.6,
        wrist_b=(0.24, -0.16, -0.04), dir_b=(0.35, -0.55, -0.2), off_b=(0.04, 0.28, 0.12), twist_b=-0.8,
        dir_c=(0.8, 0.45, -0.1), off_c=(-0.18, 0.12, 0.05), twist_c=-0.1,
        wrist_f=(0.02, 0.18, 0.45), dir_f=(0.0, 0.3, 0.95), off_f=(-0.12, 0.14, 0.12), twist_f=0.5,
    ),
    "serve_under": _Stroke(
        start=0.8, back=0.30, follow=0.25, end=0.6,
        wrist_b=(0.22, -0.26, -0.02), dir_b=(0.1, -0.7, -0.7), off_b=(-0.08, 0.28, 0.05), twist_b=-0.6,
        dir_c=(0.65, 0.35, -0.65), off_c=(-0.18, 0.10, 0.0), twist_c=-0.1,
        wrist_f=(-0.02, 0.28, 0.34), dir_f=(-0.2, 0.6, 0.75), off_f=(-0.14, 0.15, 0.10), twist_f=0.4,
    ),
}


def stroke_key(kind: str, sport: str, hit_side: float) -> str:
    """Which keyframe table animates a swing ``kind``: padel serves are underhand, tennis serves overhead,
    volleys are forehand or backhand volleys by the side of the ball (``hit_side`` > 0: racket side)."""
    if kind == "serve":
        return "serve_under" if sport == "padel" else "serve_over"
    if kind == "volley":
        return "volley_fh" if hit_side >= 0 else "volley_bh"
    return kind if kind in STROKES else "forehand"


# ------------------------------------------------------------------------------------------------------
# Small kinematics helpers (all vectorised over a leading time axis)
# ------------------------------------------------------------------------------------------------------
def _frame(yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) yaw → forward (N, 3), right (N, 3) horizontal unit vectors."""
    c, s = np.cos(yaw), np.sin(yaw)
    z = np.zeros_like(yaw)
    return np.stack([-s, c, z], -1), np.stack([c, s, z], -1)


def _to_world(off: np.ndarray, fwd: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(N, 3) offsets in a heading frame (x right, y forward, z up) → (N, 3) world vectors."""
    return off[:, :1] * right + off[:, 1:2] * fwd + off[:, 2:3] * UP


def _to_local(vec: np.ndarray, fwd: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_to_world` for (N, 3) world vectors."""
    return np.stack([np.sum(vec * right, -1), np.sum(vec * fwd, -1), vec[:, 2]], -1)


def _bend_directions(e: np.ndarray, pole: np.ndarray) -> np.ndarray:
    """Unit directions (N, 3) ⟂ the limb axes ``e`` (N, 3) towards ``pole`` (N, 3), kept continuous along
    the first (time) axis: where the pole is nearly parallel to the limb, the previous direction is carried
    over instead of letting the middle joint flip to the other side."""
    q = pole - np.sum(pole * e, -1, keepdims=True) * e
    strength = np.linalg.norm(q, axis=-1) / np.maximum(np.linalg.norm(pole, axis=-1), 1e-12)
    q = _unit(q, fallback=_unit(np.cross(e[0], [1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])))
    w = np.clip(strength / 0.5, 0.0, 1.0) ** 2
    for i in range(1, len(q)):
        if w[i] < 1.0:
            prev = q[i - 1] - (q[i - 1] @ e[i]) * e[i]
            q[i] = _unit(w[i] * q[i] + (1 - w[i]) * _unit(prev, fallback=q[i]), fallback=q[i])
    return q


def ik_two_bone(root: np.ndarray, target: np.ndarray, l1: float, l2: float, pole: np.ndarray):
    """Two-bone inverse kinematics over time.

    Args:
        root: (N, 3) first joint (shoulder, hip); target: (N, 3) wanted end (wrist, ankle).
        l1, l2: bone lengths; pole: (N, 3) direction the middle joint bends towards.
    Returns:
        middle (N, 3), end (N, 3): the end equals the target when it is within reach, otherwise it is the
        nearest reachable point on the line from the root to the target.
    """
    v = target - root
    e = _unit(v, fallback=-UP)
    d = np.clip(np.linalg.norm(v, axis=-1, keepdims=True), abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
    cos_a = np.clip((l1**2 + d**2 - l2**2) / (2 * l1 * d), -1.0, 1.0)
    q = _bend_directions(e, pole)
    mid = root + e * l1 * cos_a + q * l1 * np.sqrt(1.0 - cos_a**2)
    return mid, root + e * d


def _hermite(knot_t: np.ndarray, knot_v: np.ndarray, hold: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation through knots (constant outside them).

    Args:
        knot_t: (K,) increasing times; knot_v: (K, D) values; hold: (K,) bool, zero tangent at that knot
            (otherwise a finite-difference tangent); t: (N,) query times.
    Returns:
        (N, D) values; exactly ``knot_v[k]`` at ``knot_t[k]``.
    """
    K = len(knot_t)
    if K == 1:
        return np.repeat(knot_v[:1], len(t), axis=0)
    tan = np.zeros_like(knot_v)
    for k in range(K):
        if hold[k] or k == 0 or k == K - 1:
            continue
        tan[k] = (knot_v[k + 1] - knot_v[k - 1]) / (knot_t[k + 1] - knot_t[k - 1])
    tc = np.clip(t, knot_t[0], knot_t[-1])
    i = np.clip(np.searchsorted(knot_t, tc, side="right") - 1, 0, K - 2)
    h = (knot_t[i + 1] - knot_t[i])[:, None]
    s = ((tc - knot_t[i])[:, None]) / h
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * knot_v[i] + h10 * h * tan[i] + h01 * knot_v[i + 1] + h11 * h * tan[i + 1]


def _keep_away(target: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Push (N, 3) targets out to at least ``radius`` from (N, 3) centres (a folded arm would swing its
    elbow around wildly as the hand passes close to the shoulder)."""
    v = target - centre
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n < radius, centre + _unit(v, fallback=-UP) * radius, target)


def _smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    u = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return u * u * (3 - 2 * u)


def _bump(t: np.ndarray, centre: float, half_width: float) -> np.ndarray:
    """Raised-cosine bump: 1 at ``centre``, 0 beyond ``half_width``; (N,) → (N,)."""
    u = np.clip((t - centre) / half_width, -1.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * u))


# ------------------------------------------------------------------------------------------------------
# The body
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Style:
    """Per-player random variation."""

    build: float
    stance: float  # half the distance between the feet in the ready stance (heights)
    crouch: float  # ready-stance pelvis drop (heights)
    cadence: float  # gait frequency factor
    tempo: float  # stroke timing factor
    idle_phase: float


def _sample_style(rng: np.random.Generator) -> _Style:
    return _Style(
        build=float(rng.uniform(0.9, 1.12)),
        stance=float(rng.uniform(0.12, 0.16)),
        crouch=float(rng.uniform(0.03, 0.06)),
        cadence=float(rng.uniform(0.9, 1.1)),
        tempo=float(rng.uniform(0.88, 1.12)),
        idle_phase=float(rng.uniform(0, 2 * np.pi)),
    )


@dataclass
class _Gait:
    """Per-frame gait state: blend weight (0 standing → 1 moving), phase (rad), motion direction (T, 3),
    foot swing amplitude and lift (m)."""

    weight: np.ndarray
    phase: np.ndarray
    direction: np.ndarray
    amplitude: np.ndarray
    lift: np.ndarray


def _gait(t: np.ndarray, root: np.ndarray, fwd: np.ndarray, H: float, style: _Style) -> _Gait:
    """Leg-swing parameters from the root's speed: stride frequency and length grow with speed."""
    T = len(t)
    if T > 1:
        vel = np.gradient(root, t, axis=0)
        k = np.ones(5) / 5
        vel = np.stack([np.convolve(np.pad(vel[:, i], 2, mode="edge"), k, "valid") for i in range(2)], -1)
    else:
        vel = np.zeros((1, 2))
    speed = np.linalg.norm(vel, axis=1)
    moving = np.c_[vel / np.maximum(speed[:, None], 1e-9), np.zeros(T)]
    direction = np.where(speed[:, None] > 1e-3, moving, fwd)
    freq = style.cadence * (0.7 + 0.18 * np.minimum(speed, 7.0))  # gait cycles per second
    dt = np.diff(t, prepend=t[0])
    phase = 2 * np.pi * np.cumsum(freq * dt * _smoothstep(speed, 0.05, 0.4))
    weight = _smoothstep(speed, 0.15, 0.7)
    amplitude = weight * np.minimum(speed / (4 * freq), 0.17 * H)
    lift = weight * (0.04 + 0.02 * np.minimum(speed, 5.0))
    return _Gait(weight, phase, direction, amplitude, lift)


@dataclass
class _Contact:
    """A solved swing: its keyframe knots ``(time, priority, values (12,), hold)`` (priority 0 ready,
    1 backswing/follow-through, 2 contact), the pelvis offset it needs at the hit (lunge, crouch or jump)
    and the foot that leads (+1 right, -1 left)."""

    knots: list
    t_hit: float
    offset: np.ndarray
    half_width: float
    lead: int


class _Articulator:
    """Builds a :class:`PlayerPose` for one plan. Keyframe value layout (12): racket wrist offset (3),
    racket direction (3), other wrist offset (3) (wrist offsets from their shoulders, in heights, heading
    frame), shoulder twist, extra lean, stroke activity (0 ready, 1 stroking)."""

    def __init__(self, plan: PlayerPlan, rng: np.random.Generator, sport: str):
        self.plan, self.sport = plan, sport
        self.H = float(plan.height)
        self.side = 1.0 if plan.handed == "right" else -1.0
        self.style = _sample_style(rng)
        self.racket = RACKETS.get(sport, RACKETS["padel"])
        self.t = np.asarray(plan.t, dtype=float)
        self.root = np.asarray(plan.root, dtype=float).reshape(-1, 2)
        self.heading = np.unwrap(np.asarray(plan.heading, dtype=float))
        self.fwd, self.right = _frame(self.heading)
        self.gait = _gait(self.t, self.root, self.fwd, self.H, self.style)
        self.base_pelvis = self._base_pelvis()
        self.base_lean = 0.15 + 0.12 * self.gait.weight
        # wrist → racket head centre, wrist → handle end (m)
        self.reach_racket = BODY.hand * self.H + self.racket.head_centre - self.racket.grip
        self.reach_handle = BODY.hand * self.H - self.racket.grip

    # --- base motion -------------------------------------------------------------------------------
    def _base_pelvis(self) -> np.ndarray:
        """(T, 3) pelvis centre without strokes: root, hip height minus crouch, gait bob, idle sway."""
        g, H, st = self.gait, self.H, self.style
        crouch = (1 - g.weight) * st.crouch * H + g.weight * 0.035 * H
        bob = g.weight * 0.012 * H * 0.5 * (1 - np.cos(2 * g.phase))
        idle = (1 - g.weight) * 0.004 * H * np.sin(2 * np.pi * 0.8 * self.t + st.idle_phase)
        z = BODY.hip_height * H - crouch - bob + idle
        return np.c_[self.root, z]

    def _ready(self) -> np.ndarray:
        """Keyframe values (12,) of the ready pose."""
        return np.r_[self._wrist(_READY_WRIST, 1), self._mirror(_READY_DIR), self._wrist(_READY_OFF, -1),
                     0.0, 0.0, 0.0]

    def _wrist(self, v: tuple, shoulder: int) -> np.ndarray:
        """A table wrist offset (from the pelvis of an upright right-hander) → offset from this player's
        racket (``shoulder`` = 1) or other (-1) shoulder. Keyframes relative to the shoulders keep the
        hands' paths clear of the body however the torso leans or twists."""
        return self._mirror(v) - np.array([shoulder * self.side * BODY.shoulder_half, 0.0, BODY.spine])

    def _mirror(self, v: tuple) -> np.ndarray:
        """A right-hander's heading-frame vector for this player's hand."""
        return np.array([self.side * v[0], v[1], v[2]], dtype=float)

    def torso(self, pelvis: np.ndarray, heading: np.ndarray, twist: np.ndarray, lean: np.ndarray) -> dict:
        """Hips, shoulders and head from the pelvis centre (N, 3) and (N,) heading, twist and lean."""
        H = self.H
        f_t, r_t = _frame(heading + twist)
        _, r_h = _frame(heading + 0.4 * twist)
        spine = np.cos(lean)[:, None] * UP + np.sin(lean)[:, None] * f_t
        mid_sh = pelvis + spine * BODY.spine * H
        neck = _unit(spine + UP)
        head = mid_sh + neck * BODY.neck * H
        f_f, r_f = _frame(heading + 0.3 * twist)
        return {
            "hip_l": pelvis - r_h * BODY.hip_half * H, "hip_r": pelvis + r_h * BODY.hip_half * H,
            "sh_l": mid_sh - r_t * BODY.shoulder_half * H, "sh_r": mid_sh + r_t * BODY.shoulder_half * H,
            "head": head, "neck": neck, "face_fwd": f_f, "face_right": r_f, "torso_fwd": f_t,
        }

    # --- swings ------------------------------------------------------------------------------------
    def _interp(self, arr: np.ndarray, t: float) -> np.ndarray:
        if len(self.t) == 1:
            return arr[0]
        if arr.ndim == 1:
            return np.interp(t, self.t, arr)
        return np.array([np.interp(t, self.t, arr[:, k]) for k in range(arr.shape[1])])

    def _solve_contact(self, sw: Swing, half_width_max: float) -> _Contact:
        """Keyframes of one swing; the contact keyframe puts the racket head centre on the hit point."""
        H, s = self.H, self.side
        hit = np.asarray(sw.hit_point, dtype=float)
        t_hit = float(sw.t_hit)
        heading = float(self._interp(self.heading, t_hit))
        fwd, right = _frame(np.array([heading]))
        pelvis0 = self._interp(self.base_pelvis, t_hit)
        lateral = float((hit - pelvis0) @ right[0])
        st = STROKES[stroke_key(sw.kind, self.sport, s * lateral)]
        base_lean = float(self._interp(self.base_lean, t_hit))
        low = np.clip((0.55 * H - hit[2]) / (0.5 * H), 0.0, 1.0)
        lean_c = -0.1 if st.overhead else 0.1 + 0.5 * low
        twist_c = s * st.twist_c
        u_pref = _to_world(self._mirror(st.dir_c)[None], fwd, right)[0]
        arm = (BODY.upper_arm + BODY.forearm) * H
        shoulder_key = "sh_r" if s > 0 else "sh_l"
        offset = np.zeros(3)
        for _ in range(30):
            tor = self.torso((pelvis0 + offset)[None], np.array([heading]), np.array([twist_c]),
                             np.array([lean_c]))
            shoulder = tor[shoulder_key][0]
            u = _unit(_unit(u_pref) + 0.8 * _unit(hit - shoulder))
            wrist = hit - self.reach_racket * u
            v = wrist - shoulder
            dist = float(np.linalg.norm(v))
            lo, hi = (MIN_WRIST + 0.02) * arm, 0.97 * arm
            if dist > hi:
                offset = offset + v / dist * (dist - hi)
            elif dist < lo:
                offset = offset - v / max(dist, 1e-9) * (lo - dist)
            else:
                break
        wrist_c = _to_local((wrist - shoulder)[None] / H, fwd, right)[0]
        dir_c = _to_local(u[None], fwd, right)[0]
        tempo = self.style.tempo
        ready = self._ready()
        lean_extra = lean_c - base_lean
        half = 0.5 * lean_extra
        knots = [
            (t_hit - st.start * tempo, 0, ready, True),
            (t_hit - st.back * tempo, 1, np.r_[self._wrist(st.wrist_b, 1), self._mirror(st.dir_b),
                                                self._wrist(st.off_b, -1), s * st.twist_b, half, 1.0], False),
            (t_hit, 2, np.r_[wrist_c, dir_c, self._wrist(st.off_c, -1), twist_c, lean_extra, 1.0], False),
            (t_hit + st.follow * tempo, 1, np.r_[self._wrist(st.wrist_f, 1), self._mirror(st.dir_f),
                                                  self._wrist(st.off_f, -1), s * st.twist_f, half, 1.0],
             False),
            (t_hit + st.end * tempo, 0, ready, True),
        ]
        width = min(max(0.3, float(np.linalg.norm(offset)) / 2.0), half_width_max)
        return _Contact(knots, t_hit, offset, width, 1 if lateral >= 0 else -1)

    def _contacts(self) -> list[_Contact]:
        swings = sorted(self.plan.swings, key=lambda sw: sw.t_hit)
        hits = np.array([sw.t_hit for sw in swings], dtype=float)
        out = []
        for k, sw in enumerate(swings):
            gaps = np.abs(np.delete(hits, k) - hits[k])
            hw_max = 0.45 * float(gaps.min()) if len(gaps) else 1.0
            out.append(self._solve_contact(sw, max(hw_max, 0.05)))
        return out

    @staticmethod
    def _merge_knots(contacts: list[_Contact]) -> list:
        """All swings' knots in time order, with quick exchanges going straight from one stroke to the
        next: between consecutive swings the ready knots go when their spans overlap, the follow-through
        goes when it would end less than 0.25 s before the next backswing, and the backswing goes when it
        would start less than 0.15 s after the previous contact. Knots closer than 60 ms give way to the
        more important one."""
        keep = [[True] * 5 for _ in contacts]  # ready, backswing, contact, follow-through, ready
        for i in range(len(contacts) - 1):
            a, b = contacts[i].knots, contacts[i + 1].knots
            if a[4][0] >= b[0][0]:
                keep[i][4] = keep[i + 1][0] = False
            if a[3][0] >= b[1][0] - 0.25:
                keep[i][3] = False
            if b[1][0] <= a[2][0] + 0.15:
                keep[i + 1][1] = False
        kept = [k for c, kp in zip(contacts, keep) for k, ok in zip(c.knots, kp) if ok]
        merged: list = []
        for k in sorted(kept, key=lambda k: k[0]):
            if merged and k[0] - merged[-1][0] < 0.06:
                if k[1] > merged[-1][1]:
                    merged[-1] = k
                continue
            merged.append(k)
        return merged

    # --- assembly ----------------------------------------------------------------------------------
    def build(self) -> PlayerPose:
        contacts = self._contacts()
        track = self._track(contacts)
        pelvis, foot_shift = self._lunges(contacts)
        tor = self.torso(pelvis, self.heading, track[:, 9], self.base_lean + track[:, 10])
        (elbow_r, wrist_r), (elbow_o, wrist_o) = self._arms(tor, track)
        u = _unit(_to_world(track[:, 3:6], self.fwd, self.right))
        f_t = tor["torso_fwd"]
        normal = _unit(f_t - np.sum(f_t * u, -1, keepdims=True) * u, fallback=UP)
        (knee_l, ankle_l), (knee_r, ankle_r) = self._legs(tor, foot_shift)
        s = self.side
        wrists, elbows = {s: wrist_r, -s: wrist_o}, {s: elbow_r, -s: elbow_o}
        joints = np.stack([*self._face(tor), tor["sh_l"], tor["sh_r"], elbows[-1.0], elbows[1.0],
                           wrists[-1.0], wrists[1.0], tor["hip_l"], tor["hip_r"],
                           knee_l, knee_r, ankle_l, ankle_r], axis=1)  # COCO-17 order
        plan = self.plan
        racket = np.stack([wrist_r + u * self.reach_handle, wrist_r + u * self.reach_racket], axis=1)
        return PlayerPose(
            player_id=plan.player_id, team=plan.team, handed=plan.handed, height=self.H, t=self.t.copy(),
            joints=joints, racket=racket, racket_normal=normal, heading=self.heading.copy(),
            build=self.style.build, racket_spec=self.racket,
        )

    def _track(self, contacts: list[_Contact]) -> np.ndarray:
        """(T, 12) keyframe values at the frame times (the ready pose when there is no swing)."""
        knots = self._merge_knots(contacts)
        if not knots:
            return np.repeat(self._ready()[None], len(self.t), axis=0)
        return _hermite(np.array([k[0] for k in knots]), np.array([k[2] for k in knots]),
                        np.array([k[3] for k in knots]), self.t)

    def _lunges(self, contacts: list[_Contact]) -> tuple[np.ndarray, dict]:
        """(T, 3) pelvis with each swing's lunge/crouch/jump around its hit, and the (T, 3) shift of each
        foot (+1 right, -1 left): the leading foot steps the whole way, the other part of it."""
        pelvis = self.base_pelvis.copy()
        shift = {1: np.zeros((len(self.t), 3)), -1: np.zeros((len(self.t), 3))}
        for c in contacts:
            b = _bump(self.t, c.t_hit, c.half_width)[:, None]
            pelvis += b * c.offset
            step = np.r_[c.offset[:2], 0.0]
            jump = np.array([0.0, 0.0, max(c.offset[2], 0.0)])
            shift[c.lead] += b * (step + jump)
            shift[-c.lead] += b * (0.4 * step + jump)
        return pelvis, shift

    def _arms(self, tor: dict, track: np.ndarray):
        """Elbows and wrists (T, 3) of the racket arm and the other arm; the other arm swings with the
        gait when not stroking."""
        H, s, g, T = self.H, self.side, self.gait, len(self.t)
        free = 1 - np.clip(track[:, 11], 0.0, 1.0)
        other_off = track[:, 6:9] * H
        other_off[:, 1] -= free * 0.8 * g.amplitude * np.sin(g.phase)
        racket_sh, other_sh = (tor["sh_r"], tor["sh_l"]) if s > 0 else (tor["sh_l"], tor["sh_r"])
        l1, l2 = BODY.upper_arm * H, BODY.forearm * H
        near = MIN_WRIST * (l1 + l2)
        out = []
        for sh, off, side in ((racket_sh, track[:, 0:3] * H, s), (other_sh, other_off, -s)):
            target = _keep_away(sh + _to_world(off, self.fwd, self.right), sh, near)
            # elbows point down and a little outwards: the arm is only parallel to that when it hangs or
            # reaches straight up, and then it is nearly straight, so the elbow cannot jump far
            pole = _to_world(np.tile([side * 0.3, 0.0, -1.0], (T, 1)), self.fwd, self.right)
            out.append(ik_two_bone(sh, target, l1, l2, pole))
        return out

    def _legs(self, tor: dict, foot_shift: dict):
        """Knees and ankles (T, 3) of the left and right legs: stance width, gait swing and lift, lunges."""
        H, g = self.H, self.gait
        half_w = ((1 - g.weight) * self.style.stance + g.weight * 0.055) * H
        out = []
        for sign, hip in ((-1, tor["hip_l"]), (1, tor["hip_r"])):
            psi = g.phase + (0.0 if sign < 0 else np.pi)
            target = np.c_[self.root, np.full(len(self.t), BODY.ankle_height * H)]
            target += sign * half_w[:, None] * self.right + (g.amplitude * np.sin(psi))[:, None] * g.direction
            target[:, 2] += g.lift * np.maximum(0.0, np.cos(psi))
            pole = self.fwd + 0.2 * sign * self.right
            out.append(ik_two_bone(hip, target + foot_shift[sign], BODY.thigh * H, BODY.shank * H, pole))
        return out

    def _face(self, tor: dict) -> list[np.ndarray]:
        """(T, 3) nose, left/right eye, left/right ear."""
        H = self.H
        head_c, nd, ff, fr = tor["head"], tor["neck"], tor["face_fwd"], tor["face_right"]
        eye = head_c + ff * 0.042 * H + nd * 0.008 * H
        return [head_c + ff * 0.052 * H - nd * 0.010 * H, eye - fr * 0.018 * H, eye + fr * 0.018 * H,
                head_c - fr * 0.043 * H, head_c + fr * 0.043 * H]


def articulate(plan: PlayerPlan, fps: float, rng: np.random.Generator, *, sport: str = "padel") -> PlayerPose:
    """Animate a planned player.

    Args:
        plan: root path (T, 2), heading (T,), swings; sampled at ``plan.t`` (one time per frame).
        fps: frame rate of the clip (``plan.t`` is normally ``arange(T) / fps``; only used when ``plan.t``
            is empty).
        rng: source of the per-player style (build, stance, cadence, stroke tempo).
        sport: ``padel`` (underhand serves, 45.5 cm racket) or ``tennis`` (overhead serves, 68.5 cm racket).
    Returns:
        the :class:`PlayerPose`; at the frame whose time equals a swing's ``t_hit`` the racket head centre
        is on its ``hit_point``.
    """
    if len(plan.t) == 0:
        plan = PlayerPlan(plan.player_id, plan.team, plan.handed, plan.height, np.arange(1) / fps,
                          np.asarray(plan.root).reshape(-1, 2)[:1], np.asarray(plan.heading)[:1], plan.swings)
    return _Articulator(plan, rng, sport).build()
