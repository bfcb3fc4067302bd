"""Importers of outside pose predictions: every layout, frame bases, validation errors, round trip."""
from __future__ import annotations

import json

import numpy as np
import pytest

from inference.clipio import FormatError, PlayerTracks, write_players_csv
from inference.clipio.players import KP_COLUMNS
from inference.players.importers import load_predictions, write_mmpose_json
from inference.players.types import Persons, PoseSequence
from inference.players.skeleton import JOINT

rng = np.random.default_rng(7)


def kps(k: int = 17, x0: float = 100.0) -> np.ndarray:
    """(k, 2) distinct pixel keypoints inside a 1280x720 frame."""
    return np.stack([x0 + 3.0 * np.arange(k), 200.0 + 2.0 * np.arange(k)], axis=1)


def instance(k: int = 17, x0: float = 100.0, bbox="nested", score: float = 0.9) -> dict:
    """An MMPose instance with ``k`` keypoints; ``bbox`` is "nested", "flat" or None."""
    inst = {"keypoints": kps(k, x0).tolist(), "keypoint_scores": np.linspace(0.5, 1.0, k).tolist()}
    box = [x0 - 10, 150.0, x0 + 90, 400.0]
    if bbox == "nested":
        inst["bbox"] = [box]
    elif bbox == "flat":
        inst["bbox"] = box
    if bbox is not None:
        inst["bbox_score"] = score
    return inst


def dump(path, data):
    path.write_text(json.dumps(data))
    return path


def message(err: pytest.ExceptionInfo) -> str:
    return str(err.value)


# -------------------------------------------------------------------------------------- MMPose
def test_mmpose_inferencer_video_frames_from_zero(tmp_path):
    data = [
        {"frame_id": 0, "instances": [instance(x0=100), instance(x0=500)]},
        {"frame_id": 1, "instances": []},
        {"frame_id": 3, "instances": [instance(x0=300)]},
    ]
    seq = load_predictions(dump(tmp_path / "clip.json", data))
    assert isinstance(seq, PoseSequence) and "mmpose" in seq.source
    assert [len(p) for p in seq.frames] == [2, 0, 0, 1]  # frame 2 had no entry
    p = seq.frames[0]
    assert p.keypoints.shape == (2, 17, 2) and p.kp_scores.shape == (2, 17)
    np.testing.assert_allclose(p.keypoints[1], kps(17, 500))
    np.testing.assert_allclose(p.boxes[0], [90, 150, 190, 400])
    np.testing.assert_allclose(p.scores, [0.9, 0.9])
    assert p.track_ids.tolist() == [-1, -1]
    assert len(load_predictions(tmp_path / "clip.json", n_frames=10)) == 10


def test_mmpose_topdown_demo_frames_from_one(tmp_path):
    data = {"meta_info": {"num_keypoints": 17},
            "instance_info": [{"frame_id": 1, "instances": [instance(x0=100)]},
                              {"frame_id": 2, "instances": [instance(x0=200)]}]}
    path = dump(tmp_path / "results_clip.json", data)
    seq = load_predictions(path)
    assert len(seq) == 2
    np.testing.assert_allclose(seq.frames[0].keypoints[0], kps(17, 100))
    np.testing.assert_allclose(seq.frames[1].keypoints[0], kps(17, 200))
    shifted = load_predictions(path, frame_offset=0)  # the caller overrides the base
    assert [len(p) for p in shifted.frames] == [0, 1, 1]


def test_mmpose_topdown_demo_image(tmp_path):
    seq = load_predictions(dump(tmp_path / "r.json", {"meta_info": {}, "instance_info": [instance()]}))
    assert len(seq) == 1 and len(seq.frames[0]) == 1


def test_mmpose_single_image(tmp_path):
    seq = load_predictions(dump(tmp_path / "img.json", [instance(x0=100), instance(x0=400)]))
    assert len(seq) == 1 and len(seq.frames[0]) == 2


def test_mmpose_folder_of_frames(tmp_path):
    folder = tmp_path / "preds"
    folder.mkdir()
    dump(folder / "000012.json", [instance(x0=120)])
    dump(folder / "000003.json", [])
    dump(folder / "000005.json", [instance(x0=50), instance(x0=250)])
    seq = load_predictions(folder)
    assert len(seq) == 13
    assert len(seq.frames[5]) == 2 and len(seq.frames[12]) == 1 and len(seq.frames[3]) == 0
    np.testing.assert_allclose(seq.frames[12].keypoints[0], kps(17, 120))
    assert len(load_predictions(folder, fmt="mmpose", n_frames=20)) == 20
    assert len(load_predictions(folder, frame_offset=3).frames[2]) == 2


@pytest.mark.parametrize("bbox", ["nested", "flat", None])
def test_mmpose_bbox_forms(tmp_path, bbox):
    seq = load_predictions(dump(tmp_path / "v.json", [{"frame_id": 0, "instances": [instance(bbox=bbox)]}]))
    p = seq.frames[0]
    if bbox is None:  # the box comes from the keypoints, the score from the keypoint scores
        k = kps()
        np.testing.assert_allclose(p.boxes[0], [*k.min(axis=0), *k.max(axis=0)])
        np.testing.assert_allclose(p.scores[0], np.linspace(0.5, 1.0, 17).mean())
    else:
        np.testing.assert_allclose(p.boxes[0], [90, 150, 190, 400])
        assert p.scores[0] == pytest.approx(0.9)


@pytest.mark.parametrize("k", [17, 26, 133])
def test_mmpose_keypoint_counts_take_first_17(tmp_path, k):
    seq = load_predictions(dump(tmp_path / "v.json", [{"frame_id": 0, "instances": [instance(k)]}]))
    np.testing.assert_allclose(seq.frames[0].keypoints[0], kps(k)[:17])
    np.testing.assert_allclose(seq.frames[0].kp_scores[0], np.linspace(0.5, 1.0, k)[:17])


def test_mmpose_track_id_and_more_than_four_people(tmp_path):
    insts = [dict(instance(x0=50.0 * i), track_id=i) for i in range(7)]
    seq = load_predictions(dump(tmp_path / "v.json", [{"frame_id": 0, "instances": insts}]))
    assert seq.frames[0].track_ids.tolist() == list(range(7))


def test_scores_clipped_and_zero_score_is_missing(tmp_path):
    inst = instance()
    inst["keypoint_scores"] = [1.7] + [0.0] + [0.5] * 15
    p = load_predictions(dump(tmp_path / "v.json", [inst])).frames[0]
    assert p.kp_scores[0, 0] == 1.0
    assert p.kp_scores[0, 1] == 0.0 and np.isnan(p.keypoints[0, 1]).all()


# -------------------------------------------------------------------------------- outside frame
def test_keypoints_outside_frame_kept_wildly_outside_missing(tmp_path):
    inst = instance(bbox=None)
    inst["keypoints"][15] = [-40.0, 760.0]  # an ankle just below/left of a 1280x720 frame: kept
    inst["keypoints"][16] = [1300.0, 700.0]
    inst["keypoints"][9] = [50000.0, 300.0]  # beyond 10x the width: missing
    path = dump(tmp_path / "v.json", [inst])
    p = load_predictions(path, image_size=(1280, 720)).frames[0]
    np.testing.assert_allclose(p.keypoints[0, 15], [-40, 760])
    np.testing.assert_allclose(p.keypoints[0, 16], [1300, 700])
    assert np.isnan(p.keypoints[0, 9]).all() and p.kp_scores[0, 9] == 0
    assert p.boxes[0, 0] == -40  # the derived box ignores the missing joint
    unknown_size = load_predictions(path).frames[0]  # 50000 px is within the 1e5 px default limit
    np.testing.assert_allclose(unknown_size.keypoints[0, 9], [50000, 300])
    inst["keypoints"][9] = [-3e6, 300.0]
    assert np.isnan(load_predictions(dump(tmp_path / "w.json", [inst])).frames[0].keypoints[0, 9]).all()


def test_empty_inputs(tmp_path):
    assert len(load_predictions(dump(tmp_path / "a.json", []))) == 1  # an image with nobody
    assert len(load_predictions(dump(tmp_path / "a.json", []), n_frames=4)) == 4
    seq = load_predictions(dump(tmp_path / "b.json", [{"frame_id": 0, "instances": []}] * 1))
    assert len(seq) == 1 and len(seq.frames[0]) == 0
    assert seq.frames[0].keypoints.shape == (0, 17, 2)


# ---------------------------------------------------------------------------------------- COCO
def coco_flat(k: np.ndarray, v: np.ndarray) -> list[float]:
    return np.concatenate([k, v[:, None]], axis=1).ravel().tolist()


def test_coco_results(tmp_path):
    v = np.full(17, 2.0)
    v[3] = 0  # left ear not labelled
    results = [
        {"image_id": 4, "category_id": 1, "keypoints": coco_flat(kps(x0=100), v), "score": 0.8},
        {"image_id": 4, "category_id": 1, "keypoints": coco_flat(kps(x0=300), v), "score": 0.7,
         "bbox": [280, 150, 100, 300]},
        {"image_id": 6, "category_id": 1, "keypoints": coco_flat(kps(x0=500), np.full(17, 0.6))},
        {"image_id": 6, "category_id": 2, "keypoints": coco_flat(kps(x0=900), v)},  # not a person: skipped
    ]
    path = dump(tmp_path / "results.json", results)
    seq = load_predictions(path)
    assert "coco" in seq.source
    assert [len(p) for p in seq.frames] == [0, 0, 0, 0, 2, 0, 1]
    p = seq.frames[4]
    assert np.isnan(p.keypoints[0, 3]).all() and p.kp_scores[0, 3] == 0
    assert p.kp_scores[0, 0] == 1.0  # v = 2 (visible) -> 1
    np.testing.assert_allclose(p.boxes[1], [280, 150, 380, 450])  # xywh -> xyxy
    np.testing.assert_allclose(p.scores, [0.8, 0.7])
    assert seq.frames[6].scores[0] == pytest.approx(0.6)
    assert [len(p) for p in load_predictions(path, frame_offset=4).frames] == [2, 0, 1]


def test_coco_ground_truth_frames_from_file_names(tmp_path):
    gt = {
        "images": [{"id": 17, "file_name": "frame_000010.jpg"}, {"id": 3, "file_name": "frame_000002.jpg"}],
        "annotations": [
            {"image_id": 17, "category_id": 1, "keypoints": coco_flat(kps(), np.full(17, 2.0)),
             "num_keypoints": 17, "bbox": [90, 150, 100, 250]},
            {"image_id": 17, "category_id": 1, "iscrowd": 1, "keypoints": [0] * 51, "bbox": [0, 0, 5, 5]},
            {"image_id": 3, "category_id": 1, "keypoints": coco_flat(kps(x0=300), np.full(17, 1.0)),
             "num_keypoints": 17, "bbox": [290, 150, 100, 250]},
        ],
        "categories": [{"id": 1, "name": "person"}],
    }
    seq = load_predictions(dump(tmp_path / "person_keypoints_val.json", gt), n_frames=12)
    assert len(seq) == 12 and [len(seq.frames[i]) for i in (2, 10)] == [1, 1]
    np.testing.assert_allclose(seq.frames[10].boxes[0], [90, 150, 190, 400])
    np.testing.assert_allclose(seq.frames[2].keypoints[0], kps(x0=300))
    assert seq.frames[2].scores[0] == 1.0 and (seq.frames[2].kp_scores[0] == 1).all()


def test_coco_ground_truth_frames_from_image_order(tmp_path):
    gt = {"images": [{"id": "b", "file_name": "first.jpg"}, {"id": "a", "file_name": "second.jpg"}],
          "annotations": [{"image_id": "a", "keypoints": coco_flat(kps(), np.full(17, 2.0)),
                           "bbox": [90, 150, 100, 250]}]}
    seq = load_predictions(dump(tmp_path / "gt.json", gt), fmt="coco")
    assert [len(p) for p in seq.frames] == [0, 1]


def test_coco_ground_truth_unknown_image(tmp_path):
    gt = {"images": [{"id": 1, "file_name": "0001.jpg"}],
          "annotations": [{"image_id": 9, "keypoints": coco_flat(kps(), np.full(17, 2.0))}]}
    with pytest.raises(FormatError) as err:
        load_predictions(dump(tmp_path / "gt.json", gt))
    assert "gt.json" in message(err) and "annotations[0]" in message(err) and "image_id 9" in message(err)


# ------------------------------------------------------------------------------------ OpenPose
def body25_person(x0: float) -> dict:
    xyc = np.zeros((25, 3))
    xyc[:, 0] = x0 + np.arange(25)
    xyc[:, 1] = 300 + np.arange(25)
    xyc[:, 2] = 0.8
    xyc[18, 2] = 0.0  # LEar not found
    return {"person_id": [-1], "pose_keypoints_2d": xyc.ravel().tolist()}


def test_openpose_folder_body25_mapping(tmp_path):
    folder = tmp_path / "json"
    folder.mkdir()
    dump(folder / "clip_000000000002_keypoints.json", {"version": 1.3, "people": [body25_person(100)]})
    dump(folder / "clip_000000000000_keypoints.json", {"version": 1.3, "people": []})
    seq = load_predictions(folder)
    assert "openpose" in seq.source and [len(p) for p in seq.frames] == [0, 0, 1]
    p = seq.frames[2]
    # BODY_25 4 = RWrist -> COCO right_wrist; 16 = LEye -> left_eye; 14 = LAnkle -> left_ankle
    np.testing.assert_allclose(p.keypoints[0, JOINT["right_wrist"]], [104, 304])
    np.testing.assert_allclose(p.keypoints[0, JOINT["left_eye"]], [116, 316])
    np.testing.assert_allclose(p.keypoints[0, JOINT["left_ankle"]], [114, 314])
    np.testing.assert_allclose(p.keypoints[0, JOINT["nose"]], [100, 300])
    assert np.isnan(p.keypoints[0, JOINT["left_ear"]]).all() and p.kp_scores[0, JOINT["left_ear"]] == 0
    # BODY_25 neck (1) and mid-hip (8) are not COCO joints
    assert not np.isin([101.0, 108.0], p.keypoints[0, :, 0]).any()


def test_openpose_single_file_and_bad_length(tmp_path):
    seq = load_predictions(dump(tmp_path / "x_keypoints.json", {"people": [body25_person(10)] * 2}))
    assert len(seq) == 1 and len(seq.frames[0]) == 2
    bad = {"people": [body25_person(10), {"pose_keypoints_2d": [1.0] * 60}]}
    with pytest.raises(FormatError) as err:
        load_predictions(dump(tmp_path / "bad_keypoints.json", bad))
    assert "bad_keypoints.json" in message(err) and "person 1" in message(err) and "75" in message(err)


# --------------------------------------------------------------------------------- Ultralytics
def ul_detection(x0: float, conf: float = 0.85) -> dict:
    k = kps(x0=x0)
    return {"name": "person", "class": 0, "confidence": conf,
            "box": {"x1": x0 - 10, "y1": 150.0, "x2": x0 + 90, "y2": 400.0},
            "keypoints": {"x": k[:, 0].tolist(), "y": k[:, 1].tolist(), "visible": [0.9] * 16 + [0.0]}}


def test_ultralytics_list_over_frames(tmp_path):
    seq = load_predictions(dump(tmp_path / "yolo.json", [[ul_detection(100), ul_detection(400)], [],
                                                         [ul_detection(700)]]))
    assert "ultralytics" in seq.source and [len(p) for p in seq.frames] == [2, 0, 1]
    p = seq.frames[0]
    np.testing.assert_allclose(p.boxes[1], [390, 150, 490, 400])
    np.testing.assert_allclose(p.keypoints[0, :16], kps(x0=100)[:16])
    assert np.isnan(p.keypoints[0, 16]).all()  # visible 0
    assert p.scores[0] == pytest.approx(0.85)


def test_ultralytics_single_frame_and_folder(tmp_path):
    assert len(load_predictions(dump(tmp_path / "one.json", [ul_detection(100)])).frames[0]) == 1
    folder = tmp_path / "frames"
    folder.mkdir()
    dump(folder / "0001.json", [])
    dump(folder / "0004.json", [ul_detection(100), ul_detection(600)])
    seq = load_predictions(folder)
    assert "ultralytics" in seq.source and [len(p) for p in seq.frames] == [0, 0, 0, 0, 2]


# ----------------------------------------------------------------------------------------- CSV
def test_players_csv_needs_image_size(tmp_path):
    n = 4
    kp = rng.uniform(0.1, 0.9, (n, 17, 3))
    kp[1, 5] = np.nan
    tracks = PlayerTracks(frame=[0, 0, 2, 2], player_id=[3, 5, 3, 5], team=["near", "far"] * 2,
                          score=[0.9, 0.8, np.nan, 0.7], bbox=rng.uniform(0, 1, (n, 4)) * [0.5, 0.5, 0, 0]
                          + [0, 0, 0.6, 0.6], keypoints=kp, court_xy=np.zeros((n, 2)))
    path = write_players_csv(tmp_path / "players.csv", tracks)
    with pytest.raises(FormatError, match="image_size"):
        load_predictions(path)
    seq = load_predictions(path, image_size=(1000, 500))
    assert [len(p) for p in seq.frames] == [2, 0, 2]
    p = seq.frames[0]
    assert p.track_ids.tolist() == [3, 5]
    np.testing.assert_allclose(p.keypoints[0], kp[0, :, :2] * [1000, 500], atol=1e-3)
    np.testing.assert_allclose(p.boxes[1], tracks.bbox[1] * [1000, 500, 1000, 500], atol=1e-3)
    assert np.isnan(p.keypoints[1, 5]).all() and p.kp_scores[1, 5] == 0
    assert seq.frames[2].scores[0] == pytest.approx(seq.frames[2].kp_scores[0].mean())  # no score


def pixel_csv(tmp_path, rows: list[dict], box: bool) -> object:
    header = ["frame", "person", *KP_COLUMNS] + (["x1", "y1", "x2", "y2", "score"] if box else [])
    lines = [",".join(header)] + [",".join(str(r.get(c, "")) for c in header) for r in rows]
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def pixel_row(frame: int, person: int, x0: float, **extra) -> dict:
    row = {"frame": frame, "person": person}
    for j, (x, y) in enumerate(kps(x0=x0)):
        name = KP_COLUMNS[3 * j][:-2]
        row.update({f"{name}_x": x, f"{name}_y": y, f"{name}_s": 0.75})
    row.update(extra)
    return row


@pytest.mark.parametrize("box", [True, False])
def test_pixel_csv(tmp_path, box):
    rows = [pixel_row(1, 1, 400, x1=390, y1=150, x2=490, y2=400, score=0.6),
            pixel_row(1, 0, 100, x1=90, y1=150, x2=190, y2=400, score=0.9),
            pixel_row(3, 0, 200, left_wrist_x="", left_wrist_y="")]
    seq = load_predictions(pixel_csv(tmp_path, rows, box))
    assert "csv" in seq.source and [len(p) for p in seq.frames] == [0, 2, 0, 1]
    p = seq.frames[1]
    np.testing.assert_allclose(p.keypoints[0], kps(x0=100))  # ordered by person
    assert (p.kp_scores == 0.75).all()
    if box:
        np.testing.assert_allclose(p.boxes[0], [90, 150, 190, 400])
        np.testing.assert_allclose(p.scores, [0.9, 0.6])
    else:
        np.testing.assert_allclose(p.scores, [0.75, 0.75])
    assert np.isnan(seq.frames[3].keypoints[0, JOINT["left_wrist"]]).all()


def test_pixel_csv_errors_name_the_line(tmp_path):
    path = pixel_csv(tmp_path, [pixel_row(0, 0, 100), pixel_row(0, 0, 300)], box=False)
    with pytest.raises(FormatError) as err:
        load_predictions(path)
    assert err.value.line == 3 and "poses.csv" in message(err) and "duplicate" in message(err)
    path = pixel_csv(tmp_path, [pixel_row(0, 0, 100, nose_x="abc")], box=False)
    with pytest.raises(FormatError) as err:
        load_predictions(path)
    assert err.value.line == 2 and "nose_x" in message(err)
    path = pixel_csv(tmp_path, [pixel_row(0, 0, 100), pixel_row(9, 0, 100)], box=False)
    with pytest.raises(FormatError) as err:
        load_predictions(path, n_frames=5)
    assert err.value.line == 3 and "beyond" in message(err)
    path = pixel_csv(tmp_path, [pixel_row(0, 0, 100, x1=200, y1=150, x2=100, y2=400)], box=True)
    with pytest.raises(FormatError) as err:
        load_predictions(path)
    assert err.value.line == 2 and "x2 < x1" in message(err)


# ------------------------------------------------------------------------------------ validation
def video(*instances, frame_id=0) -> list[dict]:
    return [{"frame_id": frame_id, "instances": list(instances)}]


def bad(key, value, k=17):
    inst = instance(k)
    inst[key] = value
    return video(instance(), inst)


@pytest.mark.parametrize(
    "data, words",
    [
        (video(instance(18)), ["18 keypoints", "17 (COCO-17)", "entry 0", "instance 0"]),
        (video({"keypoint_scores": [1.0] * 17}), ["no 'keypoints'", "instance 0"]),
        (bad("keypoints", [[1.0, "x"]] * 17), ["keypoints must be numbers", "instance 1"]),
        (bad("keypoints", [[1.0, None]] * 17), ["keypoints must be numbers", "instance 1"]),
        (bad("keypoints", [[1.0, 2.0, 0.9]] * 17), ["shape (K, 2)", "instance 1"]),
        (bad("keypoints", [[1.0, float("nan")]] * 17), ["NaN or infinite", "instance 1"]),
        (bad("keypoint_scores", [0.5] * 16), ["keypoint scores", "shape (17)", "instance 1"]),
        (bad("keypoint_scores", [float("inf")] * 17), ["NaN or infinite", "instance 1"]),
        (bad("bbox", [[1.0, 2.0, 3.0]]), ["bbox", "instance 1"]),
        (bad("bbox", [300.0, 10.0, 100.0, 50.0]), ["x2 < x1", "instance 1"]),
        (bad("bbox_score", "high"), ["person score", "instance 1"]),
        (video(instance(), frame_id=-1), ["frame number -1", "frame_id -1"]),
        (video(instance(), frame_id=1.5), ["whole number", "frame_id 1.5"]),
        (video(instance()) + video(instance()), ["duplicate entry for frame 0", "entry 1"]),
        ([{"frame_id": 0}], ["no 'instances'", "entry 0"]),
        ([{"frame_id": 0, "instances": {"a": 1}}], ["must be a JSON list", "entry 0"]),
        ([{"frame_id": 0, "instances": []}, {"instances": []}], ["no 'frame_id'", "entry 1"]),
        ({"meta_info": {}}, ["cannot tell", "MMPose", "COCO", "OpenPose", "Ultralytics"]),
        ("hello", ["cannot tell"]),
    ],
)
def test_malformed_json_names_file_entry_and_fix(tmp_path, data, words):
    path = dump(tmp_path / "preds.json", data)
    with pytest.raises(FormatError) as err:
        load_predictions(path)
    text = message(err)
    assert "preds.json" in text and "fix:" in text
    for word in words:
        assert word in text


def test_frame_beyond_video(tmp_path):
    path = dump(tmp_path / "preds.json", video(instance(), frame_id=7))
    with pytest.raises(FormatError, match=r"preds.json: entry 0 \(frame_id 7\): frame 7 is beyond the video"):
        load_predictions(path, n_frames=5)
    with pytest.raises(FormatError, match="frame number 0 gives frame -1"):
        load_predictions(dump(tmp_path / "p.json", video(instance(), frame_id=0)), frame_offset=1)


def test_not_json(tmp_path):
    path = tmp_path / "preds.json"
    path.write_text('[{"frame_id": 0,\n "instances": [}]')
    with pytest.raises(FormatError) as err:
        load_predictions(path)
    assert err.value.line == 2 and "not JSON" in message(err) and "preds.json" in message(err)
    with pytest.raises(FormatError, match="file not found"):
        load_predictions(tmp_path / "missing.json")


def test_folder_errors(tmp_path):
    folder = tmp_path / "f"
    folder.mkdir()
    with pytest.raises(FormatError, match="no .json files"):
        load_predictions(folder)
    dump(folder / "a_0001.json", [instance()])
    dump(folder / "b_0001.json", [instance()])
    with pytest.raises(FormatError) as err:
        load_predictions(folder)
    assert "b_0001.json" in message(err) and "duplicate entry for frame 1 (first in a_0001.json)" in message(err)
    (folder / "b_0001.json").unlink()
    dump(folder / "last.json", [instance()])
    with pytest.raises(FormatError, match="last.json: no frame number in the file name"):
        load_predictions(folder)
    (folder / "last.json").unlink()
    dump(folder / "0002.json", [instance(), {"keypoints": [[1, 2]] * 17, "keypoint_scores": [1] * 16}])
    with pytest.raises(FormatError, match=r"0002.json: instance 1: keypoint scores"):
        load_predictions(folder)
    with pytest.raises(FormatError, match="is a folder"):
        load_predictions(folder, fmt="coco")


def test_bad_arguments(tmp_path):
    path = dump(tmp_path / "a.json", [])
    with pytest.raises(ValueError, match="fmt"):
        load_predictions(path, fmt="yolo")
    with pytest.raises(ValueError, match="image_size"):
        load_predictions(path, image_size=(0, 10))
    with pytest.raises(ValueError, match="n_frames"):
        load_predictions(path, n_frames=-1)


def test_explicit_format_mismatch(tmp_path):
    path = dump(tmp_path / "a.json", [instance()])
    with pytest.raises(FormatError, match="OpenPose frame must be a JSON object"):
        load_predictions(path, fmt="openpose")
    with pytest.raises(FormatError, match="no 'image_id'"):
        load_predictions(path, fmt="coco")


# ------------------------------------------------------------------------------------ round trip
def sequence() -> PoseSequence:
    frames = []
    for f in range(4):
        n = f % 3 + (f == 3) * 3  # 0, 1, 2, 3 people... and 5 in the last frame
        kp = rng.uniform(-50, 1330, (n, 17, 2))
        s = rng.uniform(0.1, 1.0, (n, 17))
        if n:
            kp[0, 3], s[0, 3] = np.nan, 0.0
        boxes = np.concatenate([np.nanmin(kp, 1), np.nanmax(kp, 1)], axis=1) + [-5, -5, 5, 5]
        frames.append(Persons(boxes, kp, s, rng.uniform(0, 1, n), np.arange(n)) if n else Persons.empty())
    return PoseSequence(frames, "test")


@pytest.mark.parametrize("base", [0, 1])
def test_write_mmpose_json_round_trip(tmp_path, base):
    seq = sequence()
    path = write_mmpose_json(tmp_path / "out.json", seq, frame_base=base)
    back = load_predictions(path, frame_offset=base, n_frames=len(seq))
    assert len(back) == len(seq)
    for a, b in zip(seq.frames, back.frames):
        assert len(a) == len(b)
        np.testing.assert_allclose(b.keypoints, a.keypoints)
        np.testing.assert_allclose(b.kp_scores, a.kp_scores)
        np.testing.assert_allclose(b.boxes, a.boxes)
        np.testing.assert_allclose(b.scores, a.scores)
        np.testing.assert_array_equal(b.track_ids, a.track_ids)
    assert json.loads(path.read_text())[0]["frame_id"] == base
