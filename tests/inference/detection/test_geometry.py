"""Letterbox: round trips, WASB's matrix for 16:9, padding, and consistency of points with warped images."""
from __future__ import annotations

import numpy as np
import pytest

from inference.detection import Letterbox

SIZES = [(1280, 720), (1920, 1080), (640, 480), (720, 1280), (1000, 1000), (3840, 1600), (512, 288)]


@pytest.mark.parametrize("mode", ["contain", "wasb"])
@pytest.mark.parametrize("size", SIZES)
def test_round_trip(size, mode):
    box = Letterbox(*size, mode=mode)
    pts = np.random.default_rng(0).uniform([0, 0], size, (50, 2))
    np.testing.assert_allclose(box.inverse(box.forward(pts)), pts, atol=1e-9)
    np.testing.assert_allclose(box.forward(box.inverse(pts)), pts, atol=1e-9)
    np.testing.assert_allclose(box.matrix[:, :2] @ box.inverse_matrix[:, :2], np.eye(2), atol=1e-12)


@pytest.mark.parametrize("size", SIZES)
def test_contain_fits_the_frame_centred(size):
    box = Letterbox(*size)
    x0, y0, x1, y1 = box.content_box
    assert x0 >= -1e-9 and y0 >= -1e-9 and x1 <= 512 + 1e-9 and y1 <= 288 + 1e-9
    assert np.isclose(x0, 512 - x1) and np.isclose(y0, 288 - y1)          # padding centred
    assert np.isclose(x1 - x0, 512) or np.isclose(y1 - y0, 288)           # touches one pair of sides
    np.testing.assert_allclose(box.forward([[0, 0], list(size)]), [[x0, y0], [x1, y1]])


def test_four_by_three_pads_the_sides():
    box = Letterbox(640, 480)
    assert box.scale == pytest.approx(0.6) and box.offset == pytest.approx((64.0, 0.0))


@pytest.mark.parametrize("size", [(1280, 720), (1920, 1080), (640, 480), (720, 1280)])
def test_wasb_mode_is_wasb_get_transform(size):
    """WASB: centre = image centre, scale = max(h, w) mapped to the network width."""
    w, h = size
    box = Letterbox(w, h, mode="wasb")
    k = 512 / max(w, h)
    pts = np.array([[0.0, 0.0], [w / 3, h / 5], [w, h]])
    expected = (pts - [w / 2, h / 2]) * k + [256, 144]
    np.testing.assert_allclose(box.forward(pts), expected)


def test_sixteen_by_nine_modes_agree():
    a, b = Letterbox(1280, 720), Letterbox(1280, 720, mode="wasb")
    np.testing.assert_allclose(a.matrix, b.matrix)
    np.testing.assert_allclose(a.matrix, [[0.4, 0, 0], [0, 0.4, 0]])


def _blob(w, h, centre, sigma):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2 * sigma ** 2))


def _centroid(img):
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    return np.array([(img * xx).sum(), (img * yy).sum()]) / img.sum()


@pytest.mark.parametrize("size", [(1280, 720), (640, 480), (720, 1280), (1920, 1080)])
def test_forward_points_land_where_warp_moves_the_content(size):
    """Heatmap targets drawn at forward(xy) line up with the warped frame (pixel-index convention)."""
    box = Letterbox(*size)
    centre = (size[0] * 0.37 + 0.3, size[1] * 0.61 - 0.2)
    sigma = 3.0 / box.scale                                   # 3 px on the network grid
    warped = box.warp(_blob(*size, centre, sigma).astype(np.float32))
    np.testing.assert_allclose(_centroid(warped), box.forward(centre), atol=0.05)
    back = box.unwarp(warped)
    assert back.shape == (size[1], size[0])
    np.testing.assert_allclose(_centroid(back), centre, atol=0.05 / box.scale)


def test_warp_shape_and_padding():
    box = Letterbox(640, 480)
    out = box.warp(np.full((480, 640, 3), 200, np.uint8))
    assert out.shape == (288, 512, 3) and out.dtype == np.uint8
    assert (out[:, :60] == 0).all() and (out[:, -60:] == 0).all() and (out[:, 70:440] == 200).all()
    with pytest.raises(ValueError, match=r"\(480, 640"):
        box.warp(np.zeros((720, 1280, 3), np.uint8))


def test_resized_grid_keeps_the_rule():
    box = Letterbox(1280, 720)
    half = box.resized(256, 144)
    assert half.scale == pytest.approx(0.2) and box.resized(512, 288) is box
    np.testing.assert_allclose(half.forward([[640, 360]]), [[128, 72]])


@pytest.mark.parametrize("kwargs", [dict(src_w=0, src_h=720), dict(src_w=1280, src_h=720, mode="stretch"),
                                    dict(src_w=1280, src_h=720, net_w=-1)])
def test_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        Letterbox(**kwargs)


def test_point_shapes():
    box = Letterbox(1280, 720)
    assert box.forward([640, 360]).shape == (2,)
    assert box.inverse(np.zeros((3, 4, 2))).shape == (3, 4, 2)
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        box.forward(np.zeros((4, 3)))
