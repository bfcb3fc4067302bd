"""Per-shot analytics and line calls: constructed contacts (just in, just out, on the line, padel glass
before/after the floor bounce, serves), whole simulated rallies against the simulator's own verdicts, and the
reconstructed sample clip."""
from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from inference.court import load_court
from review_fixtures import reconstructed_clip, sample_shots  # noqa: F401  (fixture)

from labeler.review.shots import (
    CSV_COLUMNS,
    Area,
    Contact,
    CourtRules,
    Trajectory,
    analyse_clip,
    analyse_rally,
    judge_shot,
    net_clearance,
    shots_csv_text,
    write_shots_csv,
)

R = 0.0328  # padel ball radius: a bounce's ball centre is this high


@pytest.fixture(scope="module")
def padel() -> CourtRules:
    return CourtRules.from_court(load_court("padel"))


@pytest.fixture(scope="module")
def tennis() -> CourtRules:
    return CourtRules.from_court(load_court("tennis"))


def ground(frame: int, x: float, y: float) -> Contact:
    return Contact(frame, "ground", (x, y, R), "floor")


def wall(frame: int, event: str, x: float, y: float, z: float = 1.0, plane: str | None = None) -> Contact:
    return Contact(frame, event, (x, y, z), plane)


# ------------------------------------------------------------------------------------------ geometry
def test_area_signed_distance_inside_outside_and_on_the_line():
    a = Area(0, 10, 10, 20, ("left", "right", "net", "far baseline"))
    assert a.signed_distance((9.5, 15)) == (pytest.approx(0.5), "right")
    assert a.signed_distance((5, 20.0)) == (0.0, "far baseline")          # on the line: in, distance 0
    d, line = a.signed_distance((5, 20.02))
    assert d == pytest.approx(-0.02) and line == "far baseline"
    d, line = a.signed_distance((11, 22))                                   # beyond a corner: Euclidean
    assert d == pytest.approx(-math.hypot(1, 2)) and line == "far baseline"
    with pytest.raises(ValueError, match="x0 < x1"):
        Area(1, 1, 0, 1, ("a", "b", "c", "d"))


def test_rules_from_the_court_yamls(padel, tennis):
    assert (padel.net_y, padel.length, padel.x_min, padel.x_max) == (10, 20, 0, 10)
    assert padel.service_y == (3.05, 16.95) and padel.centre_x == 5 and padel.walls
    assert tennis.singles and (tennis.x_min, tennis.x_max) == (1.37, 9.60) and not tennis.walls
    doubles = CourtRules.from_court(load_court("tennis"), singles=False)
    assert (doubles.x_min, doubles.x_max) == (0.0, 10.97)
    # serving from the right (x > centre) goes cross-court to the left box
    box = padel.service_box("far", server_x=7.0)
    assert (box.x0, box.x1, box.y0, box.y1) == (0, 5, 10, 16.95)
    box = tennis.service_box("near", server_x=2.0)
    assert (box.x0, box.x1, box.y0, box.y1) == (5.485, 9.60, 5.485, 11.885)


# ------------------------------------------------------------------------------------ padel rally calls
@pytest.mark.parametrize("y, call, dist_cm", [
    (19.99, "in", 1.0),      # just in: 1 cm inside the far baseline
    (20.0, "in", 0.0),       # on the line
    (20.01, "out", -1.0),    # just out
])
def test_padel_bounce_near_the_baseline(padel, y, call, dist_cm):
    verdict, _, calls = judge_shot(padel, "near", [ground(40, 5.0, y)])
    assert calls[0].call == call == verdict
    assert calls[0].distance_cm == pytest.approx(dist_cm, abs=1e-6)
    assert calls[0].line == "far baseline"


def test_padel_bounce_on_own_side_is_out(padel):
    verdict, reason, calls = judge_shot(padel, "near", [Contact(30, "net", (5, 10, 0.8)), ground(35, 5, 9.0)])
    assert verdict == "out" and calls[0].call == "out" and "own side" in reason
    assert calls[0].line == "net" and calls[0].distance_cm == pytest.approx(-100)


def test_padel_glass_before_the_floor_is_out_after_it_is_legal(padel):
    # the opponent's back glass first: out, and the later floor contact is not judged
    verdict, reason, calls = judge_shot(padel, "near", [wall(40, "wall_far", 5, 20, 1.5, "glass_far"),
                                                        ground(45, 5, 18)])
    assert verdict == "out" and "glass_far before bouncing" in reason and calls[0].call == "-"
    # floor first, then the glass: in
    verdict, _, calls = judge_shot(padel, "near", [ground(40, 5, 17), wall(45, "wall_far", 5, 20, 1.0)],
                                   volleyed=True)
    assert verdict == "in" and calls[0].call == "in"
    # side glass of the opponent's half before the floor: out; a far player's shot into its own side glass
    # (legal in padel) and then over the net: in
    assert judge_shot(padel, "near", [wall(40, "wall_left", 0, 17, 1.0), ground(44, 2, 15)])[0] == "out"
    assert judge_shot(padel, "far", [wall(40, "wall_left", 0, 17, 1.0), ground(50, 3, 6)])[0] == "in"
    # mesh before the floor is out even on the hitter's side
    assert judge_shot(padel, "far", [wall(40, "mesh", 0, 14, 2.5), ground(50, 3, 6)])[0] == "out"


def test_padel_second_bounce_and_volley(padel):
    verdict, reason, calls = judge_shot(padel, "far", [ground(40, 3, 6), ground(60, 3, 2)])
    assert verdict == "in" and [c.call for c in calls] == ["in", "-"] and "second bounce" in calls[1].reason
    assert judge_shot(padel, "far", [], volleyed=True)[:2] == ("in", "returned before the bounce (volley)")
    assert judge_shot(padel, "far", [])[0] == "-"


def test_padel_serve_box_fault_let_and_mesh(padel):
    # server on the near right (x = 7): the far left box x in [0, 5], y in [10, 16.95]
    v, _, calls = judge_shot(padel, "near", [ground(40, 4.9, 16.0)], serve=True, server_x=7.0)
    assert v == "in" and calls[0].line == "centre service line" and calls[0].distance_cm == pytest.approx(10)
    v, reason, calls = judge_shot(padel, "near", [ground(40, 4.0, 17.2)], serve=True, server_x=7.0)
    assert v == "fault" and calls[0].line == "far service line" and calls[0].distance_cm == pytest.approx(-25)
    v, _, _ = judge_shot(padel, "near", [ground(40, 6.0, 15.0)], serve=True, server_x=7.0)  # wrong box
    assert v == "fault"
    v, _, _ = judge_shot(padel, "near", [Contact(30, "net", (4, 10, 0.85)), ground(40, 3, 15)], serve=True,
                         server_x=7.0)
    assert v == "let"
    v, reason, _ = judge_shot(padel, "near", [ground(40, 1, 15), wall(45, "mesh", 0, 13, 2.0)], serve=True,
                              server_x=7.0)
    assert v == "fault" and "mesh" in reason


def test_tennis_singles_lines(tennis):
    # singles side line at x = 9.60 (far half for a near hitter)
    assert judge_shot(tennis, "near", [ground(40, 9.59, 20)])[2][0].call == "in"
    v, _, calls = judge_shot(tennis, "near", [ground(40, 9.70, 20)])
    assert v == "out" and calls[0].line == "right singles side line"
    assert calls[0].distance_cm == pytest.approx(-10)
    doubles = CourtRules.from_court(load_court("tennis"), singles=False)
    assert judge_shot(doubles, "near", [ground(40, 9.70, 20)])[0] == "in"


# -------------------------------------------------------------------------------- whole rallies, figures
def _line_path(p0, p1, frames):
    t = np.linspace(0, 1, len(frames))[:, None]
    return np.asarray(p0) + t * (np.asarray(p1) - np.asarray(p0))


def test_analyse_rally_speeds_net_clearance_and_serve_detection():
    court = load_court("padel")
    fps = 30.0
    # serve from (7, 2, 0.8) to a bounce at (3, 15, R) in 30 frames, then a return by the far team at frame 45
    f1 = np.arange(10, 41)
    xyz1 = _line_path((7, 2, 0.8), (3, 15, R), f1)
    xyz1[:, 2] += 1.2 * np.sin(np.linspace(0, np.pi, len(f1)))  # an arc over the net
    f2 = np.arange(41, 46)
    xyz2 = _line_path((3, 15.2, 0.3), (3, 16, 0.8), f2)
    f0 = np.arange(0, 10)                                      # the drop from the hand, its bounce at frame 5
    xyz0 = np.column_stack([np.full(10, 7.0), np.full(10, 2.0), np.abs(f0 - 5) * 0.15 + R])
    traj = Trajectory(np.r_[f0, f1, f2], np.vstack([xyz0, xyz1, xyz2]))
    contacts = [Contact(5, "ground", xyz0[5], "floor"), Contact(10, "player_near", xyz1[0]),
                Contact(40, "ground", xyz1[-1], "floor"), Contact(45, "player_far", xyz2[-1])]
    a = analyse_rally(court, traj, contacts, fps)
    s0, s1 = a.shots
    assert s0.serve and not s1.serve and s0.verdict == "in" and s0.first_bounce.target == "far left service box"
    step = np.linalg.norm(xyz1[3] - xyz1[2]) * fps * 3.6
    assert s0.launch_speed_kmh == pytest.approx(step, abs=0.1)
    # clearance: the path's height where it crosses y = 10, minus the radius and the net top at x there
    k = np.flatnonzero(xyz1[:, 1] >= 10)[0]
    f = (10 - xyz1[k - 1, 1]) / (xyz1[k, 1] - xyz1[k - 1, 1])
    p = xyz1[k - 1] + f * (xyz1[k] - xyz1[k - 1])
    top = 0.88 + (0.92 - 0.88) * abs(p[0] - 5) / 5
    assert s0.net_clearance_m == pytest.approx(p[2] - R - top, abs=1e-3)
    assert net_clearance(court, xyz1[:5]) != net_clearance(court, xyz1[:5])  # NaN: no crossing
    # a first hit in front of the service line is not a serve (the clip started mid-rally)
    moved = [contacts[0], Contact(10, "player_near", (7, 5, 0.8)), *contacts[2:]]
    assert not analyse_rally(court, traj, moved, fps).shots[0].serve
    # a clip cut mid-rally: the ball came over from the far side and bounced before the first hit
    incoming = Trajectory(traj.frame, np.vstack([_line_path((3, 9, 1.5), (7, 2, R), f0), xyz1, xyz2]))
    assert not analyse_rally(court, incoming, contacts, fps).shots[0].serve
    late = Trajectory(traj.frame[10:], traj.xyz[10:])        # the track starts at the hit: no set-up seen
    assert not analyse_rally(court, late, contacts[1:], fps).shots[0].serve


@pytest.mark.parametrize("sport", ["padel", "tennis"])
def test_calls_agree_with_the_simulators_verdicts(sport):
    """The simulator judges every rally's last shot itself (winner, out, net, glass); our calls on its
    exact contacts must agree."""
    from synth.rally import simulate_rally

    court = load_court(sport)
    expected = {"winner": {"in"}, "error_out": {"out", "fault"}, "error_wall": {"out", "fault"},
                "error_net": {"out", "fault", "-"}}
    seen = set()
    for seed in range(12):
        rally = simulate_rally(court, fps=30.0, rng=np.random.default_rng(seed))
        frames = np.arange(rally.n_frames)
        traj = Trajectory(frames, rally.ball.sample(frames / rally.fps))
        contacts = [Contact(int(round(c.t * rally.fps)), c.event, c.position, c.plane) for c in rally.contacts]
        a = analyse_rally(court, traj, contacts, rally.fps)
        assert a.shots, f"seed {seed}: no shots"
        assert a.shots[0].serve, f"seed {seed}: the first hit is the serve"
        last = a.shots[-1]
        assert last.verdict in expected[rally.outcome], (seed, rally.outcome, last.verdict, last.reason)
        for s in a.shots[:-1]:  # every shot before the last was returned, so it was good
            assert s.verdict in ("in", "let"), (seed, s.index, s.verdict, s.reason)
            assert 5 < s.launch_speed_kmh < 250
        seen.add(rally.outcome)
    assert "winner" in seen and len(seen) >= 2


def test_sample_clip_reconstruction_and_csv(reconstructed_clip, tmp_path):
    """The sample's shots (one per racket hit of its events.csv) agree with its ground truth. The far player's
    lob (hit 147) crosses the net above the top of the picture (ball.csv has no 2D ball there): the review
    still gives its figures and call from the 3D of the hidden frames."""
    from inference.clipio import Clip

    clip = Clip(reconstructed_clip)
    rec = analyse_clip(clip)
    gt = analyse_clip(clip, gt=True)
    expected = sample_shots()
    assert len(rec.shots) == len(gt.shots) == len(expected)
    assert [(s.hit.frame, s.team) for s in rec.shots] == [(f, team) for f, team, _ in expected]
    with_bounce = [k for k, (*_, bounced) in enumerate(expected) if bounced]
    assert with_bounce == list(range(len(expected) - 1))  # only the last, cut by the clip's end, has none
    traj = Trajectory.from_ball_3d(clip.read_ball_3d())
    visible = clip.read_ball().visibility > 0
    net_y = load_court("padel").net_y
    crossing_hidden = []
    for k in with_bounce:
        r, g = rec.shots[k], gt.shots[k]
        assert r.has_3d and r.verdict == g.verdict == "in"
        assert np.linalg.norm(r.first_bounce.xy - g.first_bounce.xy) < 0.15   # metres
        assert abs(r.launch_speed_kmh - g.launch_speed_kmh) < 3
        # the net crossing: between the last frame before the net plane and the first beyond it
        frames, xyz = traj.window(r.hit.frame, r.first_bounce.frame)
        i = int(np.flatnonzero(np.diff(np.sign(xyz[:, 1] - net_y)))[0])
        if visible[frames[i]] and visible[frames[i + 1]]:
            assert abs(r.net_clearance_m - g.net_clearance_m) < 0.05
        else:
            # above the picture the height at the net is the ballistic fit's extrapolation between the two
            # seen ends of the flight; it must agree with the truth within the 2σ ball_3d.csv states there
            crossing_hidden.append(r.hit.frame)
            f = int(frames[i])
            sigma_z = math.sqrt(float(traj.cov_near(f, f, f)[2, 2]))
            assert abs(r.net_clearance_m - g.net_clearance_m) < 2 * sigma_z
    assert crossing_hidden == [147]  # the far player's lob, the one flight that leaves the picture
    assert rec.pre_serve and rec.pre_serve[0].call == "-"
    path = write_shots_csv(tmp_path / "shots.csv", rec)
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == len(expected)
    assert rows[0]["serve"] == "1" and rows[0]["call"] == "in" and float(rows[0]["line_distance_cm"]) > 0
    assert shots_csv_text(rec) == path.read_text()
