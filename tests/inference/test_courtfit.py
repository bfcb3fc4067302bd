"""The automatic court fit on rendered views (venue, players, noise, JPEG) and its gate; `calibrate --auto`."""
from __future__ import annotations

import copy
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from inference.camera import Camera
from inference.cli import main
from inference.clipio import Clip, write_video
from inference.court import load_court
from inference.courtfit import AutoFitError, fit_court, fit_court_frames, sample_frame_indices
import inference.courtfit.fit as fitmod
from inference.courtfit.fit import (MIN_K2_REACH, _distance_to_polylines, _evidence_reach, _line_distance_map,
                                    _undistorted, confused_segments, unexplained_share)
from inference.courtfit.lines import LineEvidence, background, hough_lines, line_mask, working_scale
from inference.courtfit.model import court_lines
from inference.courtfit.search import elevation_deg, find_lines, split_lines
from synth.generate import SynthConfig, SynthScene

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample" / "padel_sample"
FLOOR = ["near_left", "near_right", "far_left", "far_right", "near_service_left", "near_service_center",
         "near_service_right", "far_service_left", "far_service_center", "far_service_right", "net_left",
         "net_right"]


def _scene_frames(sport: str, preset: str, seed: int, n: int = 7) -> tuple[SynthScene, list[np.ndarray]]:
    scene = SynthScene.build(seed, SynthConfig(sport=sport, camera=preset, width=1280, height=720))
    look = scene.look
    # the test is about the realistic look: players, venue, sensor noise and JPEG all on
    assert look.jpeg_quality is not None and look.noise_sigma > 0.5 and scene.rally.players
    return scene, [scene.frame(i)[0] for i in sample_frame_indices(scene.rally.n_frames, n)]


def _floor_rms(cam: Camera, gt: Camera, court) -> float:
    pts = court.point_array(FLOOR)
    px = gt.project(pts)
    pts = pts[((px >= 0) & (px <= np.array(gt.image_size))).all(1)]
    return float(np.sqrt(np.mean(np.sum((cam.project(pts) - gt.project(pts)) ** 2, axis=1))))


@pytest.mark.parametrize("sport, preset, seed", [("padel", "padel_broadcast", 4), ("tennis", "tennis_broadcast", 0), ("tennis", "tennis_high", 2)])
def test_fit_finds_the_court_in_a_realistic_view(sport, preset, seed):
    scene, frames = _scene_frames(sport, preset, seed)
    fit = fit_court_frames(frames, scene.court)
    gt = scene.camera
    assert fit.accepted, fit.summary()
    assert fit.confidence > 0.3 and fit.coverage > 0.8
    assert np.linalg.norm(fit.camera.centre - gt.centre) < 0.3
    assert abs(fit.camera.K[0, 0] / gt.K[0, 0] - 1) < 0.03
    assert _floor_rms(fit.camera, gt, scene.court) < 2.0
    assert fit.camera.source == "auto" and fit.camera.meta["auto"]["accepted"] is True
    # the fitted floor points are in the image and close to the true ones
    pts = fit.court_points(scene.court)
    assert len(pts) >= 8
    err = [np.linalg.norm(xy - gt.project(scene.court.points[n][None])[0]) for n, xy in pts.items()]
    assert np.median(err) < 2.0


def test_gate_refuses_a_view_without_a_court():
    rng = np.random.default_rng(0)
    frames = [np.clip(90 + rng.normal(0, 4, (720, 1280, 3)), 0, 255).astype(np.uint8) for _ in range(3)]
    fit = fit_court_frames(frames, load_court("padel"))
    assert not fit.accepted and fit.reason
    with pytest.raises(AutoFitError, match="click court points"):
        fit.require()


def test_gate_refuses_the_wrong_court_model():
    """Padel lines fitted with the tennis model: no placement explains them well enough to pass."""
    scene, frames = _scene_frames("padel", "padel_broadcast", 4, n=5)
    fit = fit_court_frames(frames, load_court("tennis"))
    assert not fit.accepted, fit.summary()
    assert "REJECTED" in fit.summary()


def _goals_met(fit, scene) -> bool:
    gt = scene.camera
    return (np.linalg.norm(fit.camera.centre - gt.centre) <= 0.3 and abs(fit.camera.K[0, 0] / gt.K[0, 0] - 1) <= 0.03
            and _floor_rms(fit.camera, gt, scene.court) <= 2.0)


def test_near_rail_marks_the_painted_line_it_runs_along():
    """Installed camera right behind the glass (bench seed 519): the near glass's top rail lies over the near
    service line in the image; a broadcast view (far behind the glass) and tennis (no walls) have no such line."""
    model = court_lines(load_court("padel"))
    installed = SynthScene.build(519, SynthConfig(sport="padel", camera="padel_installed")).camera
    flagged = confused_segments(installed, model, 1280 / max(installed.image_size))
    near_service = [i for i, (a, b) in enumerate(model.segments_3d) if a[1] == b[1] == 3.05]
    assert flagged.tolist() == [i in near_service for i in range(len(flagged))]
    broadcast = SynthScene.build(4, SynthConfig(sport="padel", camera="padel_broadcast")).camera
    assert not confused_segments(broadcast, model, 1280 / max(broadcast.image_size)).any()
    tennis = court_lines(load_court("tennis"))
    assert len(tennis.structure) == 0 and not confused_segments(installed, tennis, 1.0).any()


@pytest.mark.parametrize("seed, accepted, why, camera_right", [
    (519, True, "", True), (909, True, "", True), (617, False, "lie on none", False),
    (1001, False, "nothing pins the near court", False),
    (517, True, "", True), (507, True, "", True), (501, True, "", True), (711, True, "", True), (613, True, "", True),
    (1209, True, "", True), (1213, True, "", True), (1217, True, "", True),
    (1415, False, "nearest painted line across", False), (1555, False, "nearest painted line across", False),
    (1649, True, "", True)])
def test_installed_camera_behind_the_glass_is_fitted_or_refused_never_wrong(seed, accepted, why, camera_right):
    """The bench's installed padel views (drawn size, half with lens distortion): 519 — the rail hides the near
    service line, whose paint pulled the fit onto the rail's lower edge (5 px off); refitted from a fit
    without that paint, the rails are reached and found along their whole length, and the close rivals would
    each be refused on their own: accepted, right; 909 — the same kind of view with dark rails (found along
    under 40 % of their length): refitted with the rails and the paint, the fit stayed 2.5 px off and a rival
    fitted almost as well (refused); the refit without that paint, started with the net's tape in its
    place, explains a third more line pixels and lands within 0.3 px: accepted, right; 617 — the best placement found is 5 px off (the near service line on the rail) and leaves half
    the painted line pixels on its floor unexplained: refused; 1001 — the near service line runs along the
    rail and neither is found along its length (dark rails): the near court is placed by the side lines
    alone, 3 px off: refused; 517 — the rail runs along the near
    service line, fitted with the rails as lines of their own; 507 — mild barrel distortion, k1 kept; 501 — the
    best-scoring placement lays the court on the rails (its floor paint unexplained), the next one is right;
    711 — the only close rival would itself be refused (most of its floor paint unexplained), so it is no
    rival; 613 — the near fence's mesh gives many strong transverse lines in one band of the image, which
    must not crowd out the court's far lines (before, the court was laid on the rails and refused); 1209 and
    1213 — strong barrel distortion (k1 −0.085 / −0.050 with k2 0.034 / 0.017): k1 alone left the near lines
    2–5 px off (1209 refused, 1213 accepted 2.8 px off); k1 and k2 fit them within 1.2 px; 1217 — a bright
    rail hides the near service line: the refit without it, started with the net's tape, is 1.3 px off
    (6 px before); 1415, 1555 — the near service line hidden below a dark rail, the fit lays it on the
    fence's lowest wires 9 / 13 px off (accepted before): refitted without it, the other lines and the net put
    it 12 working px away: refused; 1649 — a strong barrel lens (k1 −0.149) bends the near lines so much that
    the straight-line search finds no right placement (see the next test): found on the undistorted background.
    An accepted fit is always within the goals; a refused one says why."""
    scene = SynthScene.build(seed, SynthConfig(sport="padel", camera="padel_installed"))
    frames = [scene.frame(i)[0] for i in sample_frame_indices(scene.rally.n_frames, 9)]
    fit = fit_court_frames(frames, scene.court)
    assert fit.accepted == accepted, fit.summary()
    if fit.accepted:
        assert fit.unexplained < 0.45
    else:
        assert why in fit.reason
    if camera_right:
        assert _goals_met(fit, scene), fit.summary()


def test_strong_barrel_lens_is_found_by_the_search_on_the_undistorted_background(monkeypatch):
    """Bench seed 1649 (installed view, k1 −0.149): with straight-line search alone every placement found
    lays the court on the rails and is refused; the second search, on the background undistorted by a
    guessed lens, finds the court, and the fit on the real line pixels recovers k1."""
    scene = SynthScene.build(1649, SynthConfig(sport="padel", camera="padel_installed"))
    frames = [scene.frame(i)[0] for i in sample_frame_indices(scene.rally.n_frames, 9)]
    fit = fit_court_frames(frames, scene.court)
    assert fit.accepted and _goals_met(fit, scene), fit.summary()
    assert abs(fit.camera.dist[0] - scene.camera.dist[0]) < 0.02
    monkeypatch.setattr(fitmod, "DISTORTION_SEARCH", ())
    plain = fit_court_frames(frames, scene.court)
    assert not plain.accepted and "net is not where" in plain.reason


def test_undistorted_background_straightens_a_line_bent_by_the_lens():
    """A straight line drawn through a barrel lens (image k1 −0.15) is straight again after
    :func:`_undistorted` with the same lens, and stays bent without it."""
    W, H = 1280, 720
    f0, k = 0.5 * np.hypot(W, H), -0.15
    img = np.zeros((H, W), np.uint8)
    xu = np.linspace(-0.8, 0.8, 6000)
    yu = 0.35 + 0.05 * xu  # a straight line in ideal (undistorted) coordinates, half-diagonals about the centre
    g = 1 + k * (xu**2 + yu**2)
    xd, yd = W / 2 + f0 * xu * g, H / 2 + f0 * yu * g
    img[np.round(yd).astype(int), np.round(xd).astype(int)] = 255

    def straightness(im):
        ys, xs = np.nonzero(im > 100)
        A = np.stack([xs, np.ones_like(xs)], 1).astype(float)
        coef, *_ = np.linalg.lstsq(A, ys.astype(float), rcond=None)
        return float(np.max(np.abs(A @ coef - ys)))

    assert straightness(img) > 8.0
    assert straightness(_undistorted(img, k, (W, H), 1.0)) < 1.5


def test_k2_is_not_tried_when_the_lines_stay_near_the_centre():
    """k2 is only pinned by line pixels far out: pixels along the court lines within 40 % of the way to the
    corners reach under :data:`MIN_K2_REACH`; the whole court seen from the installed camera, whose view it
    fills, reaches more."""
    scene = SynthScene.build(519, SynthConfig(sport="padel", camera="padel_installed", width=1280, height=720))
    cam, model = scene.camera, court_lines(scene.court)
    pts, _ = model.samples(0.02)
    px = cam.project(np.concatenate([pts, np.zeros((len(pts), 1))], axis=1))
    centre = np.array([640.0, 360.0])
    r = np.linalg.norm(px - centre, axis=1) / np.linalg.norm(centre)
    inside = np.isfinite(px).all(1) & (px >= 0).all(1) & (px[:, 0] < 1280) & (px[:, 1] < 720)
    assert _evidence_reach(cam, model, px[inside & (r < 0.4)], 1.0) < 0.4 < MIN_K2_REACH
    assert _evidence_reach(cam, model, px[inside], 1.0) > MIN_K2_REACH


@pytest.mark.parametrize("seed", [3012, 3004])
def test_tour_broadcast_view_is_fitted(seed):
    """The bench's padel_tour views from the tour camera (a tour event as broadcast, issue 45's real kind):
    bright rails and posts, dense transverse structure, the outline unpainted and the glass on bright base
    profiles, floor logos, a score box, an advertising board. Refused before (3012, 960×540: the court's
    lines along the view crowded out of the line search, the court laid 34 m off on the walls' rails; 3004,
    1080p with a lens: the far service line marked as confused with the near fence's top, a rival 1.12×
    short of the margin then needed); now accepted with the camera right. The floor points stay a few px
    off (under 0.4 % of the image width): the fit places the unpainted outline on the base profiles just
    outside it (an offset fitted as an unknown set rendered views right but moved the real frame's camera
    0.8 m: not adopted)."""
    scene = SynthScene.build(seed, SynthConfig(sport="padel", camera="padel_tv", venue="tour"))
    frames = [scene.frame(i)[0] for i in sample_frame_indices(scene.rally.n_frames, 9)]
    fit = fit_court_frames(frames, scene.court)
    gt = scene.camera
    assert fit.accepted, fit.summary()
    assert np.linalg.norm(fit.camera.centre - gt.centre) < 0.3
    assert abs(fit.camera.K[0, 0] / gt.K[0, 0] - 1) < 0.03
    assert _floor_rms(fit.camera, gt, scene.court) < 0.004 * gt.image_size[0]


def test_far_lines_beside_the_near_fence_top_are_not_marked():
    """A tour broadcast camera high behind the court (the real view of issue 45: 7 m up, 14 m behind the near
    glass) sees the near fence's top rail (4 m) just beside the far service line and baseline in the image.
    Only paint of the near half can be confused with a near rail: the far lines stay ordinary lines."""
    model = court_lines(load_court("padel"))
    tv = SynthScene.build(3012, SynthConfig(sport="padel", camera="padel_tv", venue="tour")).camera
    scale = 1280 / max(tv.image_size)
    assert not confused_segments(tv, model, scale).any()
    mesh_top = tv.project(np.array([[5.0, 0.0, 4.0]]))[0, 1]
    far_service = tv.project(np.array([[5.0, 16.95, 0.0]]))[0, 1]
    assert abs(mesh_top - far_service) * scale < 16  # CONFUSION_PX: close enough to have been marked before


def test_court_lines_along_the_view_are_kept_under_dense_transverse_structure():
    """A broadcast view is crossed by dense strong transverse lines (rails, a fence's wires, boards, a score
    box); their slightly tilted copies filled the 48 Hough lines of a real padel frame (46 transverse, the
    centre line and the side walls' bases missing). The lines along the view are searched on their own, and
    shallow lines that only collect the transverse lines' pixels where they cross them are not kept."""
    w, h = 1280, 720
    mask = np.zeros((h, w), np.uint8)
    for k in range(50):
        cv2.line(mask, (0, 150 + 4 * k), (w - 1, 150 + 4 * k), 1, 1)
    for x0, x1 in ((420, 330), (860, 950)):  # two court lines along the view, below the band
        cv2.line(mask, (x0, 400), (x1, 700), 1, 1)
    ev = LineEvidence.from_mask(mask.astype(bool), 1.0, (w, h))
    assert not any(abs(k.angle_deg) >= 18 for k in hough_lines(ev))  # all 48 transverse
    _, longi = split_lines(find_lines(ev), (w, h))
    assert sorted(round(k.angle_deg) for k in longi) == [-73, 73]


def test_edge_on_placements_are_implausible():
    """A placement that lays the court on a wall's rails and posts seen edge-on puts the camera far away and
    low (rendered tour view 3012, its glass joints drawn bright, was accepted 129 m away, 7 m high, before
    this check): it sees the floor under 5°."""
    centre = np.array([5.0, 10.0])
    assert elevation_deg(np.array([5.0, -13.8, 7.0]), centre) > 15  # the real tour camera
    assert elevation_deg(np.array([5.5, -36.9, 10.0]), np.array([5.485, 11.885])) > 10  # a real tennis camera
    assert elevation_deg(np.array([9.9, -128.7, 7.1]), centre) < 5


def test_unexplained_share_is_low_for_the_true_camera_and_high_for_a_shifted_one():
    """The share of line pixels on the court's floor that no modelled line explains: near zero for the true
    camera of a broadcast view, far higher when the court is placed 2 m off along its length."""
    scene = SynthScene.build(4, SynthConfig(sport="padel", camera="padel_broadcast"))
    frames = [scene.frame(i)[0] for i in sample_frame_indices(scene.rally.n_frames, 5)]
    w, h = scene.camera.image_size
    scale = working_scale((w, h))
    ev = LineEvidence.from_mask(line_mask(background(frames, scale)), scale, (w, h))
    right = unexplained_share(scene.camera, scene.court, ev)
    moved = copy.deepcopy(scene.camera)
    moved.t = moved.t - moved.R @ np.array([0.0, 2.0, 0.0])  # the camera 2 m farther along y
    assert right < 0.15
    assert unexplained_share(moved, scene.court, ev) > right + 0.3


def test_line_distance_map_agrees_with_the_exact_distance():
    """The rasterised distance to projected lines (used for the unexplained share: is a line pixel within a
    few px of a line?) is within 2 px of the exact point-to-polyline distance up to 5 px (a thin rasterised
    line strays up to ~1 px from the true one), also for lines
    that leave the image or pass behind the camera (pixels 5 px inside the border: beyond it a line outside
    the image is not drawn)."""
    rng = np.random.default_rng(3)
    scale, shape = 0.5, (180, 320)
    polys = rng.uniform(-200, 900, size=(6, 24, 2))
    polys[2, :5] = np.nan  # part of a line behind the camera
    polys[4] = np.linspace([-5000.0, 100.0], [700.0, 300.0], 24)  # from far outside into the image
    dmap = _line_distance_map(polys, scale, shape)
    ys, xs = np.mgrid[5:shape[0] - 5:3, 5:shape[1] - 5:3]
    pix = (np.stack([xs.ravel(), ys.ravel()], axis=1) + 0.5) / scale - 0.5
    kept = polys.copy()
    kept[4] = np.where((np.abs((kept[4] + 0.5) * scale - 0.5) < 4 * max(shape)).all(1, keepdims=True), kept[4], np.nan)
    exact = _distance_to_polylines(pix, kept) * scale
    near = np.minimum(dmap[ys.ravel(), xs.ravel()], 5.0)
    assert (exact < 3.0).sum() > 50
    err = np.abs(near - np.minimum(exact, 5.0))
    assert np.max(err) < 2.0 and np.median(err) < 0.5


# ------------------------------------------------------------------------------------------ the CLI
@pytest.fixture(scope="module")
def broadcast_source(tmp_path_factory) -> Path:
    """A rendered padel broadcast clip (120 frames, 1280×720) with its clicked points and ground truth."""
    out = tmp_path_factory.mktemp("broadcast")
    assert main(["synth", "--sport", "padel", "--clips", "1", "--seed", "4", "--camera", "padel_broadcast",
                 "--fixed-camera", "--size", "1280x720", "--max-frames", "120", "--out", str(out)]) == 0
    return out / "clip_0000"


@pytest.fixture
def sample_clip(tmp_path, broadcast_source) -> Path:
    """The broadcast clip without its camera and court points (what a user starts from)."""
    root = tmp_path / "clip"
    shutil.copytree(broadcast_source, root)
    for name in ("camera.yaml", "court_points.csv"):
        (root / name).unlink(missing_ok=True)
    return root


def test_calibrate_auto_refuses_the_demo_sample_and_says_why(tmp_path, capsys):
    """The embedded sample's installed camera: the near service line is hidden behind the near glass's rail
    and the dark rails are not found, so the fit (2.7 px off on the floor points) is refused; nothing is
    written and the user is sent to click points."""
    root = tmp_path / "sample"
    shutil.copytree(SAMPLE, root)
    for name in ("camera.yaml", "court_points.csv"):
        (root / name).unlink(missing_ok=True)
    assert main(["calibrate", str(root), "--auto"]) == 1
    err = capsys.readouterr().err
    assert "nothing pins the near court" in err and "rally3d label" in err
    assert not (root / "camera.yaml").exists() and not (root / "court_points.csv").exists()


def test_calibrate_auto_writes_camera_and_points_to_correct(sample_clip, capsys):
    assert main(["calibrate", str(sample_clip), "--auto"]) == 0
    out = capsys.readouterr().out
    assert "automatic court fit accepted" in out
    cam = Camera.load(sample_clip / "camera.yaml")
    gt = Camera.load(sample_clip / "gt" / "camera.yaml")
    assert cam.source == "auto" and cam.meta["auto"]["accepted"] is True
    assert np.linalg.norm(cam.centre - gt.centre) < 0.3
    # the fitted points are a court_points.csv a person can correct in the labeler; they calibrate alike
    points = Clip(sample_clip).read_court_points(known_names=load_court("padel").point_names)
    assert len(points) >= 6
    assert main(["calibrate", str(sample_clip), "--dry-run"]) == 0
    assert "plane calibration" in capsys.readouterr().out


def test_calibrate_auto_leaves_clicked_points_alone(sample_clip, broadcast_source, capsys):
    clicked = (broadcast_source / "court_points.csv").read_text()
    (sample_clip / "court_points.csv").write_text(clicked)
    assert main(["calibrate", str(sample_clip), "--auto", "--frames", "0,40,80,110"]) == 0
    assert (sample_clip / "court_points.csv").read_text() == clicked
    assert (sample_clip / "court_points_auto.csv").is_file()
    assert Camera.load(sample_clip / "camera.yaml").meta["auto"]["frames"] == [0, 40, 80, 110]


def test_calibrate_auto_refuses_and_writes_nothing_without_a_court(tmp_path, capsys):
    root = tmp_path / "grey"
    root.mkdir()
    write_video(root / "video.mp4", [np.full((360, 640, 3), 90, np.uint8) for _ in range(5)], fps=25.0)
    (root / "clip.yaml").write_text("sport: padel\nfps: 25\nwidth: 640\nheight: 360\nvideo: video.mp4\n")
    assert main(["calibrate", str(root), "--auto"]) == 1
    assert "not reliable" in capsys.readouterr().err
    assert not (root / "camera.yaml").exists() and not (root / "court_points.csv").exists()


def test_infer_with_court_points_auto_calibrates_the_video(sample_clip, tmp_path, capsys):
    out = tmp_path / "result"
    code = main(["infer", str(sample_clip / "video.mp4"), "--court", "padel", "--court-points", "auto",
                 "--out", str(out), "--no-progress", "--pose", "none", "--only", "camera"])
    text = capsys.readouterr().out
    assert code == 0, text
    cam = Camera.load(out / "camera.yaml")
    assert cam.source == "auto"
    assert np.linalg.norm(cam.centre - Camera.load(sample_clip / "gt" / "camera.yaml").centre) < 0.3
    assert "automatic court fit accepted" in text


def test_fit_court_reads_a_clip_folder(sample_clip):
    fit = fit_court(Clip(sample_clip), load_court("padel"), frames=[0, 50, 100])
    assert fit.frames == [0, 50, 100] and fit.accepted
    assert fit.cpu_seconds > 0
