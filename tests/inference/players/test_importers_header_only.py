"""A pose CSV with its header and no row (the tool found nobody) is an empty result (``n_frames`` frames
without people), never a ValueError from inside NumPy."""
from __future__ import annotations

import pytest

from inference.players.importers import BOX_COLUMNS, PIXEL_CSV_COLUMNS, load_predictions


@pytest.mark.parametrize("columns", [PIXEL_CSV_COLUMNS, (*PIXEL_CSV_COLUMNS, *BOX_COLUMNS, "score")])
def test_header_only_pose_csv_is_nobody_in_any_frame(columns, tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text(",".join(columns) + "\n")
    seq = load_predictions(path, n_frames=5, image_size=(1280, 720))
    assert len(seq.frames) == 5 and all(len(p) == 0 for p in seq.frames)
    assert seq.source.startswith("csv:")
    assert len(load_predictions(path).frames) == 0  # no frame count given: no frame named, none
