"""Pose on tiles around the people of the look before: the geometry, and the clip loop against whole frames."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from inference.clipio import Clip
from inference.court import load_court
from inference.players import Persons
from inference.players.crops import CropLooks, TileMemory, inside_tile, non_max, tiles_around
from inference.players.evaluate import score
from inference.players.tracking import TrackingConfig, players_from_poses

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"


def persons(boxes, scores) -> Persons:
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    kp = np.repeat(((boxes[:, :2] + boxes[:, 2:]) / 2)[:, None], 17, axis=1)
    return Persons(boxes, kp, np.ones((len(boxes), 17)), scores)


def test_tiles_grow_merge_and_stay_inside_the_frame():
    # two players side by side share one tile; one far away gets its own; one at the corner is clipped
    tiles = tiles_around([[100, 100, 140, 200], [150, 100, 190, 200], [500, 300, 520, 340], [0, 420, 30, 480]],
                         (480, 640), margin=0.35)
    assert len(tiles) == 3
    assert (tiles[:, [0, 1]] >= 0).all() and (tiles[:, 2] <= 640).all() and (tiles[:, 3] <= 480).all()
    both = tiles[(tiles[:, 0] < 100) & (tiles[:, 2] > 190) & (tiles[:, 1] < 100)]
    assert len(both) == 1                                       # one tile holds both players of the pair
    far = tiles[tiles[:, 0] > 400][0]
    assert far[2] - far[0] == far[3] - far[1] == pytest.approx(40 * 1.7, abs=1)  # square on the larger side
    corner = tiles[tiles[:, 1] > 300][0]
    assert corner[0] == 0 and corner[3] == 480


def test_a_person_cut_by_a_tiles_edge_is_dropped_but_not_at_the_frames_edge():
    tile = np.array([100, 100, 300, 300])
    p = persons([[150, 150, 200, 250], [95, 150, 130, 250], [250, 150, 300, 250]], [0.9, 0.9, 0.9])
    assert inside_tile(p, tile, (1000, 1000)).tolist() == [True, False, False]
    # the same tile at the frame's right and bottom edge: a person touching those is whole
    assert inside_tile(p, tile, (300, 300)).tolist() == [True, False, True]


def test_non_max_keeps_the_stronger_of_two_copies():
    p = persons([[0, 0, 10, 20], [1, 0, 11, 20], [50, 50, 60, 70]], [0.5, 0.8, 0.3])
    kept = non_max(p)
    assert sorted(kept.scores.tolist()) == [0.3, 0.8]


def test_the_memory_follows_people_keeps_a_missed_one_and_flags_a_lost_confident_one():
    cfg = CropLooks(memory=2)
    mem = TileMemory.of(persons([[0, 0, 20, 40], [100, 0, 120, 40], [300, 0, 310, 20]], [0.9, 0.3, 0.05]), 0.1)
    assert len(mem) == 2                                    # below the tracker's threshold: no tile
    # the confident one moved, the weak one is missed by this look, somebody new shows up
    assert not mem.update(persons([[5, 2, 25, 42], [200, 100, 220, 140]], [0.6, 0.5]), cfg)
    assert len(mem) == 3 and mem.boxes[0].tolist() == [5, 2, 25, 42] and mem.age.tolist() == [0, 1, 0]
    assert not mem.update(persons([[6, 2, 26, 42], [200, 100, 220, 140]], [0.6, 0.5]), cfg)
    assert mem.update(persons([[200, 100, 220, 140]], [0.5]), cfg)   # the confident one is gone: a whole look
    assert mem.age.tolist() == [1, 0]                       # the weak one, missed 3 looks in a row, is forgotten
    with pytest.raises(ValueError, match="full_every"):
        CropLooks(full_every=0)


@pytest.fixture(scope="module")
def movenet():
    from inference.players.backends import MoveNetBackend

    backend = MoveNetBackend()
    ok, reason = backend.available()
    if not ok:
        pytest.skip(reason)
    return backend


def test_tile_looks_track_the_players_as_whole_frames_do(movenet):
    """On the rendered tennis sample, posing tiles on most looks keeps both players, their court positions
    within a few cm of whole-frame looks, and looks at a fraction of the pixels."""
    from inference.players.backends import MoveNetBackend

    clip = Clip(SAMPLE / "tennis_sample")
    camera, court = clip.read_camera(gt=True), load_court(clip.court_path())
    gt = clip.read_players(gt=True)
    active = np.zeros(clip.n_frames, bool)
    active[:90] = True
    results = {}
    for name, crops in (("whole", None), ("tiles", CropLooks())):
        backend = MoveNetBackend(crops=crops)
        seq = backend.run(clip, progress=False, active=active, stride=2)
        players = players_from_poses(seq, camera, court, clip.info.fps, TrackingConfig(), active=active)
        results[name] = (players, dict(backend.looks), score(players, gt, clip.info.fps))
    whole, tiles = results["whole"], results["tiles"]
    assert whole[1]["tiles"] == 0
    assert tiles[1]["tiles"] >= 0.6 * (tiles[1]["tiles"] + tiles[1]["full"])   # most looks are tiles
    assert tiles[0].ids() == whole[0].ids() and len(tiles[0].ids()) == 2
    assert tiles[2].coverage >= whole[2].coverage - 0.05
    assert tiles[2].median_error_m <= whole[2].median_error_m + 0.05
    assert tiles[2].switches == 0


def test_a_tile_that_loses_its_player_falls_back_to_the_whole_frame(movenet):
    """A confident person seen before where the frame now shows nobody (the tile is empty stands) makes the
    look a whole-frame one, which finds the real players; a tile that shows its person stays a tile look."""
    clip = Clip(SAMPLE / "tennis_sample")
    frame = clip.frames()[40]
    whole = movenet.infer(frame)
    movenet.looks = {"full": 0, "tiles": 0}
    movenet._since_full = 0
    ghost = persons([[5, 5, 40, 80]], [0.95])            # the top-left corner: stands and sky, no player
    movenet._memory = TileMemory.of(ghost, 0.1)
    found = movenet.look(frame, start=False)
    assert movenet.looks == {"full": 1, "tiles": 0}
    assert len(found) == len(whole) and np.allclose(found.boxes, whole.boxes)
    movenet._since_full = 0
    again = movenet.look(frame, start=False)                  # the players are where they were: tiles suffice
    assert movenet.looks == {"full": 1, "tiles": 1} and movenet.last_tiled
    assert (again.scores >= 0.2).sum() >= 2
