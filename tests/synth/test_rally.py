"""The rally planner: rules, reach, movement limits, timing and determinism over many seeds."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from inference.court import load_court
from synth.rally import Zones, default_config, simulate_rally

SEEDS = range(30)
FPS = 30.0


@lru_cache(maxsize=None)
def simulated(sport: str):
    """(court, config, rallies of 30 seeds), simulated once per test session."""
    court = load_court(sport)
    rallies = [simulate_rally(court, FPS, np.random.default_rng(s)) for s in SEEDS]
    return court, default_config(sport), rallies


@pytest.fixture(params=["padel", "tennis"])
def sport_rallies(request):
    return simulated(request.param)


def hits(rally):
    return [c for c in rally.contacts if c.player is not None]


def root_at(plan, t):
    return np.array([np.interp(t, plan.t, plan.root[:, k]) for k in range(2)])


def test_many_seeds_simulate(sport_rallies):
    court, cfg, rallies = sport_rallies
    assert len(rallies) == len(SEEDS)
    n_hits = [len(hits(r)) for r in rallies]
    assert min(n_hits) >= 1 and max(n_hits) <= cfg.n_hits[1]
    assert np.mean(n_hits) > 4
    # a rally of one hit is an ace (tennis serves at broadcast speed): a winner, the serve bounced in
    aces = [r for r in rallies if len(hits(r)) == 1]
    assert all(r.outcome == "winner" and any(c.event == "ground" for c in r.contacts) for r in aces)
    assert len(aces) <= 0.2 * len(rallies)  # real men's final: 5 % aces, 16 % unreturned serves
    outcomes = {r.outcome for r in rallies}
    assert "winner" in outcomes and outcomes & set(cfg.errors)
    assert all(r.sport == court.sport for r in rallies)


def test_every_plane_contact_lies_on_its_plane_within_its_extent(sport_rallies):
    court, _, rallies = sport_rallies
    r = court.ball.radius
    for rally in rallies:
        times = [c.t for c in rally.contacts]
        assert times == sorted(times)
        for c in rally.contacts:
            if c.player is not None:
                assert c.plane is None and c.event in ("player_near", "player_far")
                continue
            plane = court.plane(c.plane)
            assert c.event == plane.event
            assert abs(abs(float((c.position - plane.origin) @ plane.normal)) - r) < 1e-3
            assert plane.contains(c.position[None])[0]
            assert np.allclose(rally.ball.sample(np.array([c.t]))[0], c.position, atol=1e-3)


def test_racket_contacts_are_within_reach_on_the_stroke_side(sport_rallies):
    court, _, rallies = sport_rallies
    for rally in rallies:
        for c in hits(rally):
            plan = rally.players[c.player]
            assert c.event == f"player_{plan.team}"
            swing = next(s for s in plan.swings if s.t_hit == c.t)
            assert np.allclose(swing.hit_point, c.position)
            offset = c.position[:2] - root_at(plan, c.t)
            assert 0.2 <= np.linalg.norm(offset) <= 1.0, (swing.kind, offset)
            forward = np.array([0.0, Zones.forward(plan.team)])
            right = np.array([forward[1], -forward[0]])
            lateral = float(offset @ right) * (1 if plan.handed == "right" else -1)  # + = forehand side
            if swing.kind in ("forehand", "serve", "overhead"):
                assert lateral > 0.15, (swing.kind, lateral)
            if swing.kind == "backhand":
                assert lateral < -0.15
            z = c.position[2]
            if swing.kind == "serve" and court.sport == "padel":
                assert z < 0.55 * plan.height  # underhand, below the waist
            elif swing.kind == "serve":
                assert 2.6 <= z <= 3.0
            else:
                assert 0.3 <= z <= 2.9


def test_serve_is_from_behind_the_line_and_bounces_in_the_diagonal_box(sport_rallies):
    court, _, rallies = sport_rallies
    z = Zones.of(court, 0.0)
    for rally in rallies:
        serve, ret = (hits(rally) + [None])[:2]  # no return: an ace
        server = rally.players[serve.player]
        root = root_at(server, serve.t)
        line = z.service_depth if court.sport == "padel" else z.half
        assert z.depth(server.team, root[1]) > line
        until = ret.t if ret is not None else np.inf
        bounces = [c for c in rally.contacts if serve.t < c.t < until and c.event == "ground"]
        assert len(bounces) == 1 if ret is not None else len(bounces) >= 1
        box = "left" if root[0] > z.centre_x else "right"
        receiver_team = "far" if server.team == "near" else "near"
        assert z.in_box(receiver_team, box, bounces[0].position[:2])


def test_hits_alternate_and_bounces_obey_the_rules(sport_rallies):
    court, _, rallies = sport_rallies
    z = Zones.of(court, 0.0)
    for rally in rallies:
        hs = hits(rally)
        teams = [rally.players[h.player].team for h in hs]
        assert all(a != b for a, b in zip(teams, teams[1:]))
        for h, nxt, team in zip(hs, hs[1:], teams):
            receiver = "far" if team == "near" else "near"
            between = [c for c in rally.contacts if h.t < c.t < nxt.t]
            floor = [c for c in between if c.event == "ground"]
            assert len(floor) <= 1  # a volley or one bounce
            assert "net" not in [c.event for c in between]
            if floor:
                assert z.in_half(receiver, floor[0].position[:2])
                # padel: no glass or mesh before the floor bounce
                first = between[0]
                assert first.event == "ground"
            else:
                assert court.sport == "padel"  # volleys only in padel
                assert all(c.event == "ground" for c in between)  # (nothing at all)


def test_rally_ends_as_its_outcome_says(sport_rallies):
    court, _, rallies = sport_rallies
    z = Zones.of(court, 0.0)
    for rally in rallies:
        last = hits(rally)[-1]
        team = rally.players[last.player].team
        opp = "far" if team == "near" else "near"
        after = [c for c in rally.contacts if c.t > last.t]
        dead = rally.ball.t[np.flatnonzero(rally.ball.in_play)[-1]]
        if rally.outcome == "winner":
            floor = [c for c in after if c.event == "ground"]
            assert floor and z.in_half(opp, floor[0].position[:2])
            if len(floor) >= 2:
                assert dead == pytest.approx(floor[1].t, abs=1e-6)
        else:
            first = after[0]
            assert dead == pytest.approx(first.t, abs=1e-6)
            if rally.outcome == "error_net":
                assert first.event == "net"
            elif rally.outcome == "error_wall":
                assert first.event.startswith("wall") or first.event == "mesh"
            else:
                assert first.event == "ground" and not z.in_half(opp, first.position[:2])


def test_ball_path_covers_the_clip_densely_with_lead_and_tail(sport_rallies):
    _, cfg, rallies = sport_rallies
    for rally in rallies:
        b = rally.ball
        assert b.t[0] == 0.0 and b.t[-1] >= (rally.n_frames - 1) / rally.fps - 1e-9
        assert np.all(np.diff(b.t) > 0)
        assert np.max(np.diff(b.t)) <= 1 / (10 * rally.fps) + 1e-9  # ≥ 10 samples per frame
        assert b.pos.shape == b.vel.shape == b.spin.shape == (len(b.t), 3)
        play = np.flatnonzero(b.in_play)
        assert np.all(np.diff(play) == 1)  # one interval
        t_serve, t_dead = b.t[play[0]], b.t[play[-1]]
        assert t_serve == pytest.approx(hits(rally)[0].t, abs=1e-9)
        assert cfg.lead[0] - 1e-9 <= t_serve <= cfg.lead[1] + 1e-9
        assert cfg.tail[0] - 0.05 <= rally.n_frames / rally.fps - t_dead <= cfg.tail[1] + 0.05
        assert np.all(b.pos[:, 2] >= -0.5)


def test_launch_speeds_are_in_the_sport_ranges(sport_rallies):
    court, cfg, rallies = sport_rallies
    serve_lo, serve_hi = cfg.shots["serve"].speed
    shots = [s for name, s in cfg.shots.items() if name != "serve"]
    lo, hi = min(s.speed[0] for s in shots), max(s.speed[1] for s in shots)
    for rally in rallies:
        for i, h in enumerate(hits(rally)):
            k = np.searchsorted(rally.ball.t, h.t)
            speed = np.linalg.norm(rally.ball.vel[k])
            if i == 0:
                assert serve_lo - 0.01 <= speed <= serve_hi + 0.01
            else:
                assert lo - 0.01 <= speed <= hi + 0.01
            spin = np.linalg.norm(rally.ball.spin[k]) / (2 * np.pi)
            assert spin <= 55.0
    if court.sport == "padel":
        assert hi <= 25.0
    else:
        assert serve_lo >= 35.0 and hi <= 35.0


def test_players_move_and_turn_within_limits_on_their_side(sport_rallies):
    court, cfg, rallies = sport_rallies
    z = Zones.of(court, 0.0)
    for rally in rallies:
        assert len(rally.players) == cfg.n_players
        for plan in rally.players:
            assert plan.root.shape == (rally.n_frames, 2) and plan.heading.shape == (rally.n_frames,)
            assert np.allclose(plan.t, np.arange(rally.n_frames) / rally.fps)
            speed = np.linalg.norm(np.diff(plan.root, axis=0), axis=1) * rally.fps
            assert speed.max() <= cfg.player.speed[1] + 1e-6
            assert np.all(z.depth(plan.team, plan.root[:, 1]) > 0.3)  # never at or over the net
            assert np.all(np.abs(plan.heading) <= np.pi + 1e-9)
            yaw = np.unwrap(plan.heading)
            assert np.abs(np.diff(yaw)).max() * rally.fps <= cfg.player.turn_rate + 1e-6
            assert [s.t_hit for s in plan.swings] == sorted(s.t_hit for s in plan.swings)
            forward = 0.0 if plan.team == "near" else np.pi
            for s in plan.swings:  # facing the net at the stroke
                off = np.interp(s.t_hit, plan.t, yaw) - forward
                assert abs((off + np.pi) % (2 * np.pi) - np.pi) < 0.2


def test_padel_balls_come_back_off_the_glass_and_get_volleyed():
    _, _, rallies = simulated("padel")
    off_glass = volleys = 0
    for rally in rallies:
        hs = hits(rally)
        for h, nxt in zip(hs, hs[1:]):
            between = [c.event for c in rally.contacts if h.t < c.t < nxt.t]
            off_glass += any(e.startswith("wall") for e in between)
            volleys += not between
    assert off_glass >= 10 and volleys >= 5


def test_inactive_balls_lie_on_the_floor_away_from_feet(sport_rallies):
    court, cfg, rallies = sport_rallies
    counts = [len(r.inactive_balls) for r in rallies]
    assert max(counts) <= cfg.inactive.count[1] and max(counts) > 0
    for rally in rallies:
        for b in rally.inactive_balls:
            assert b.position[2] == pytest.approx(court.ball.radius)
            assert 0 <= b.first <= b.last < rally.n_frames
            for plan in rally.players:
                assert np.linalg.norm(plan.root[b.first : b.last + 1] - b.position[:2], axis=1).min() > 0.5


def test_same_seed_gives_the_same_rally():
    court = load_court("padel")
    a, b = (simulate_rally(court, FPS, np.random.default_rng(7)) for _ in range(2))
    c = simulate_rally(court, FPS, np.random.default_rng(8))
    assert a.n_frames == b.n_frames and a.outcome == b.outcome
    for f in ("t", "pos", "vel", "spin", "in_play"):
        assert np.array_equal(getattr(a.ball, f), getattr(b.ball, f))
    assert [(x.t, x.event, x.plane, x.player) for x in a.contacts] == [
        (x.t, x.event, x.plane, x.player) for x in b.contacts
    ]
    for pa, pb in zip(a.players, b.players):
        assert np.array_equal(pa.root, pb.root) and np.array_equal(pa.heading, pb.heading)
        assert [s.t_hit for s in pa.swings] == [s.t_hit for s in pb.swings]
    assert [(i.position.tolist(), i.first, i.last) for i in a.inactive_balls] == [
        (i.position.tolist(), i.first, i.last) for i in b.inactive_balls
    ]
    assert c.n_frames != a.n_frames or not np.array_equal(c.ball.pos[:100], a.ball.pos[:100])


def test_high_frame_rates_get_finer_substeps():
    rally = simulate_rally(load_court("tennis"), 120.0, np.random.default_rng(3))
    assert np.max(np.diff(rally.ball.t)) <= 1 / 1200 + 1e-9
    assert rally.n_frames == int(np.floor(rally.ball.t[-1] * 120 + 1e-6)) + 1


def test_unknown_sport_and_player_count_are_rejected():
    with pytest.raises(KeyError, match="no rally configuration"):
        simulate_rally(load_court("padel"), FPS, np.random.default_rng(0), sport="squash")
    with pytest.raises(ValueError, match="n_players"):
        simulate_rally(load_court("padel"), FPS, np.random.default_rng(0), n_players=3)


def _rally_shot_flights(config, n: int = 24) -> np.ndarray:
    """Seconds from each rally shot (a racket hit that is not the serve) to the bounce that follows it."""
    court, out = load_court("tennis"), []
    for k in range(n):
        ev = simulate_rally(court, 50.0, np.random.default_rng(900 + k), sport="tennis", config=config).event_frames()
        hits = [i for i, (_, e) in enumerate(ev) if e.startswith("player")]
        out += [(ev[i + 1][0] - ev[i][0]) / 50.0 for i in hits[1:] if i + 1 < len(ev) and ev[i + 1][1] == "ground"]
    return np.array(out)


def test_tennis_at_tour_pace_flies_as_fast_as_a_real_final():
    """The tour pace's rally shots reach their bounce as soon as a real men's final's do (median 0.86 s
    measured on real points), the club pace's a quarter of a second later; padel has no tour pace."""
    tour = _rally_shot_flights(default_config("tennis", "tour"))
    club = _rally_shot_flights(default_config("tennis"))
    assert len(tour) > 30 and len(club) > 30
    assert 0.78 <= np.median(tour) <= 0.95 and np.median(club) >= np.median(tour) + 0.12
    with pytest.raises(KeyError, match="no tour rally configuration for sport 'padel'"):
        default_config("padel", "tour")


def test_tour_players_rally_from_deep_behind_the_baseline():
    """At a tour final's pace the players hit from 1–5 m behind the baseline (real broadcasts' 3D contacts:
    1.8–4.5 m), at the club pace from about the baseline; serves stay at the baseline."""
    court = load_court("tennis")

    def behind(config):
        out = []
        for k in range(16):
            r = simulate_rally(court, 50.0, np.random.default_rng(300 + k), sport="tennis", config=config)
            hits = [c for c in r.contacts if c.event.startswith("player") and c.in_rally]
            assert abs(hits[0].position[1] - (0.0 if hits[0].event == "player_near" else 23.77)) < 0.5  # serve
            out += [-c.position[1] if c.event == "player_near" else c.position[1] - 23.77 for c in hits[1:]]
        return np.array(out)

    tour, club = behind(default_config("tennis", "tour")), behind(default_config("tennis"))
    assert len(tour) > 30 and len(club) > 30
    assert 1.5 <= np.median(tour) <= 3.0 and np.quantile(tour, 0.9) >= 3.5
    assert np.median(club) <= 0.8
