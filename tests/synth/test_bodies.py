"""Articulated players: human proportions, racket on the hit point at the hit time, smooth motion."""
from __future__ import annotations

import numpy as np
import pytest

from synth.bodies import (
    BODY,
    CAPSULE_MATERIALS,
    CAPSULE_NAMES,
    RACKETS,
    articulate,
    capsules,
)
from synth.types import COCO17, PlayerPlan, Swing

FPS = 30.0
J = {name: i for i, name in enumerate(COCO17)}


def plan(root_start=(5.0, 3.0), root_end=None, heading=0.0, swings=(), n=60, height=1.8, handed="right"):
    """A hand-built plan: a straight root path (or standing still) at constant heading."""
    t = np.arange(n) / FPS
    end = root_start if root_end is None else root_end
    root = np.c_[np.linspace(root_start[0], end[0], n), np.linspace(root_start[1], end[1], n)]
    return PlayerPlan(0, "near", handed, height, t, root, np.full(n, heading), list(swings))


def bone(pose, a, b):
    return np.linalg.norm(pose.joints[:, J[a]] - pose.joints[:, J[b]], axis=-1)


@pytest.mark.parametrize("height", [1.6, 1.8, 1.95])
def test_standing_body_is_human_proportioned(height):
    pose = articulate(plan(height=height), FPS, np.random.default_rng(0))
    assert pose.joints.shape == (60, 17, 3) and pose.racket.shape == (60, 2, 3)
    for side in ("left", "right"):
        for a, b, length in (("shoulder", "elbow", BODY.upper_arm), ("elbow", "wrist", BODY.forearm),
                             ("hip", "knee", BODY.thigh), ("knee", "ankle", BODY.shank)):
            np.testing.assert_allclose(bone(pose, f"{side}_{a}", f"{side}_{b}"), length * height, rtol=1e-6)
    shoulders = bone(pose, "left_shoulder", "right_shoulder")
    np.testing.assert_allclose(shoulders, 2 * BODY.shoulder_half * height, rtol=1e-6)
    # upright: feet on the floor, head on top, in a slightly crouched ready stance
    caps = capsules(pose, 0)
    top = max(max(a[2], b[2]) + r for a, b, r in caps)
    bottom = min(min(a[2], b[2]) - r for a, b, r in caps)
    assert 0.9 * height < top < 1.02 * height
    assert -0.03 < bottom < 0.03
    nose = pose.joints[:, J["nose"], 2]
    assert np.all((nose > 0.85 * height) & (nose < 0.95 * height))
    assert np.all(pose.joints[:, [J["left_ankle"], J["right_ankle"]], 2] < 0.1)
    # the pelvis is between the feet, the shoulders above the hips
    assert np.all(pose.joints[:, J["left_shoulder"], 2] > pose.joints[:, J["left_hip"], 2] + 0.2 * height)


def test_capsules_cover_the_body():
    pose = articulate(plan(), FPS, np.random.default_rng(1))
    caps = capsules(pose, 10)
    assert len(caps) == len(CAPSULE_NAMES) == len(CAPSULE_MATERIALS)
    radii = {name: r for name, (_, _, r) in zip(CAPSULE_NAMES, caps)}
    assert all(a.shape == (3,) and b.shape == (3,) for a, b, _ in caps)
    assert 0.06 < radii["head"] < 0.11 and 0.08 < radii["torso_left"] < 0.13
    assert radii["forearm_left"] < radii["upper_arm_left"] < radii["thigh_left"]
    # every joint lies inside some capsule
    a = np.array([c[0] for c in caps])
    b = np.array([c[1] for c in caps])
    r = np.array([c[2] for c in caps])
    for p in pose.joints[10]:
        ab = b - a
        s = np.clip(np.sum((p - a) * ab, 1) / np.maximum(np.sum(ab * ab, 1), 1e-12), 0, 1)
        assert np.min(np.linalg.norm(a + s[:, None] * ab - p, axis=1) - r) < 0.02


SWINGS = [
    ("forehand", (5.9, 3.4, 0.9)), ("backhand", (4.2, 3.4, 1.0)), ("volley", (5.6, 3.6, 1.3)),
    ("overhead", (5.2, 3.3, 2.6)), ("serve", (5.5, 3.4, 0.75)), ("lob", (5.8, 3.4, 0.5)),
    ("forehand", (7.2, 3.6, 0.3)),  # out of reach: the body lunges and crouches
]


@pytest.mark.parametrize("sport", ["padel", "tennis"])
@pytest.mark.parametrize(("kind", "hit"), SWINGS)
def test_racket_head_is_on_the_hit_point_at_the_hit_time(sport, kind, hit):
    swing = Swing(t_hit=1.0, hit_point=np.array(hit), kind=kind)
    for handed in ("right", "left"):
        pose = articulate(plan(swings=[swing], handed=handed), FPS, np.random.default_rng(2), sport=sport)
        frame = round(swing.t_hit * FPS)
        assert np.linalg.norm(pose.racket[frame, 1] - swing.hit_point) < 0.03
        # the racket is held: its handle is near the wrist of the racket hand
        wrist = pose.joints[frame, J[f"{handed}_wrist"]]
        assert np.linalg.norm(pose.racket[frame, 0] - wrist) < 0.1
        np.testing.assert_allclose(np.linalg.norm(pose.racket[:, 1] - pose.racket[:, 0], axis=1),
                                   RACKETS[sport].head_centre, atol=1e-6)
        # the stroke moves the racket: pulled back before, followed through after
        assert np.linalg.norm(pose.racket[frame - 8, 1] - pose.racket[frame, 1]) > 0.2
        assert np.linalg.norm(pose.racket[frame + 8, 1] - pose.racket[frame, 1]) > 0.2


def test_serves_are_underhand_in_padel_and_overhead_in_tennis():
    padel_serve = Swing(1.0, np.array([5.5, 3.4, 0.75]), "serve")
    tennis_serve = Swing(1.0, np.array([5.3, 3.3, 2.7]), "serve")
    padel = articulate(plan(swings=[padel_serve]), FPS, np.random.default_rng(3))
    tennis = articulate(plan(swings=[tennis_serve]), FPS, np.random.default_rng(3), sport="tennis")
    f = 30
    assert padel.racket[f, 1, 2] < padel.joints[f, J["right_wrist"], 2]  # head below the hand
    assert tennis.racket[f, 1, 2] > tennis.joints[f, J["right_wrist"], 2]  # head above the hand
    assert tennis.joints[f, J["right_wrist"], 2] > tennis.joints[f, J["nose"], 2]  # arm up


def test_motion_is_continuous():
    p = plan((4.0, 3.0), (8.0, 7.0), heading=0.3, n=100)
    fwd, right = np.array([-np.sin(0.3), np.cos(0.3), 0]), np.array([np.cos(0.3), np.sin(0.3), 0])

    def hit_near(t, side, z):
        root = np.r_[p.root[round(t * FPS)], 0.0]
        return root + 0.7 * side * right + 0.35 * fwd + [0, 0, z]

    p.swings = [Swing(0.8, hit_near(0.8, 1, 1.0), "forehand"),
                Swing(1.5, hit_near(1.5, 0.2, 2.5), "overhead"),
                Swing(1.9, hit_near(1.9, -1, 1.2), "volley"), Swing(2.6, hit_near(2.6, 1, 0.4), "lob")]
    pose = articulate(p, FPS, np.random.default_rng(4))
    step = np.linalg.norm(np.diff(pose.joints, axis=0), axis=-1)
    assert step.max() < 12.0 / FPS  # no joint faster than 12 m/s
    assert np.linalg.norm(np.diff(pose.racket, axis=0), axis=-1).max() < 40.0 / FPS
    assert np.isfinite(pose.joints).all() and np.isfinite(pose.racket).all()
    for sw in p.swings:
        assert np.linalg.norm(pose.racket[round(sw.t_hit * FPS), 1] - sw.hit_point) < 0.03


def test_gait_swings_the_legs_more_when_running():
    def stride(speed):
        pose = articulate(plan((2.0, 3.0), (2.0 + speed * 2.0, 3.0), heading=np.pi / 2, n=60), FPS,
                          np.random.default_rng(5))
        rel = pose.joints[:, J["left_ankle"], 0] - pose.joints[:, [J["left_hip"], J["right_hip"]], 0].mean(1)
        lift = pose.joints[:, J["left_ankle"], 2].max() - pose.joints[:, J["left_ankle"], 2].min()
        return np.ptp(rel[10:-10]), lift

    standing, walking, running = stride(0.0), stride(0.8), stride(5.0)
    assert standing[0] < 0.02 and standing[1] < 0.02
    assert walking[0] > 0.2 and walking[1] > 0.04
    assert running[0] > walking[0] and running[1] > walking[1]


def test_same_rng_gives_the_same_pose():
    swings = [Swing(1.0, np.array([5.9, 3.4, 0.9]), "forehand")]
    a = articulate(plan(swings=swings), FPS, np.random.default_rng(7))
    b = articulate(plan(swings=swings), FPS, np.random.default_rng(7))
    np.testing.assert_array_equal(a.joints, b.joints)
    np.testing.assert_array_equal(a.racket, b.racket)
