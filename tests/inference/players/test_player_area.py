"""Players where tennis and padel players really are: a returner 5 m behind the baseline is kept, a line
judge standing beside the court and a spectator in the stands are not."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import FormatError
from inference.court import load_court
from inference.players.tracking import Track, TrackingConfig, on_court, select_players

FPS = 30.0


def _track(path: np.ndarray) -> Track:
    """A person following ``path`` (T, 2) court metres, one row a frame."""
    n = len(path)
    return Track(np.arange(n), np.tile([0.0, 0.0, 10.0, 30.0], (n, 1)), np.zeros((n, 17, 2)), np.ones((n, 17)),
                 np.ones(n), np.asarray(path, float))


def _moving(x0: float, y0: float, n: int = 120, amp: float = 1.5, seed: int = 0) -> np.ndarray:
    """Someone moving around (x0, y0) as a player does between shots."""
    t = np.arange(n) / FPS
    rng = np.random.default_rng(seed)
    return np.stack([x0 + amp * np.sin(1.3 * t + rng.uniform(0, 6)), y0 + 0.6 * amp * np.sin(0.9 * t)], 1)


def test_a_tennis_returner_far_behind_the_baseline_is_kept_and_the_line_judge_is_not():
    court = load_court("tennis")
    near = _track(_moving(5.5, -5.0))                         # returning serve 5 m behind the near baseline
    far = _track(_moving(5.5, 23.77 + 3.0, seed=1))
    judge = _track(np.tile([-2.5, 2.0], (120, 1)) + 0.05)     # a line judge standing beside the near half
    umpire = _track(np.tile([-1.5, 11.9], (120, 1)))          # the umpire's chair at the net post
    chosen = select_players([judge, near, umpire, far], court, FPS, TrackingConfig())
    assert [t is near for t in chosen] == [True, False] and chosen[1] is far


def test_a_spectator_in_the_stands_is_no_player():
    court = load_court("tennis")
    fan = _track(_moving(-9.0, 6.0, amp=2.0))                 # moving about in the stands beside the court
    assert not on_court(fan.court, court, 1.5).any()
    assert select_players([fan], court, FPS, TrackingConfig()) == []


def test_padel_players_may_leave_through_the_side_doors_but_the_stands_are_out():
    court = load_court("padel")
    door = np.array([[-2.0, 10.0], [12.0, 9.0]])              # outside the glass, by the net: through a door
    stands = np.array([[-2.0, 2.0], [5.0, -3.0]])             # beside the back glass, behind it
    assert on_court(door, court, 1.5).all() and not on_court(stands, court, 1.5).any()


def test_a_bad_player_area_is_named(tmp_path):
    text = (load_court("tennis").source.read_text()
            .replace("player_area: [[-5.0, 15.97, -8.0, 31.77]]", "player_area: [[5.0, 1.0, 0.0, 1.0]]"))
    bad = tmp_path / "tennis.yaml"
    bad.write_text(text)
    with pytest.raises(FormatError, match="player_area"):
        load_court(bad)
