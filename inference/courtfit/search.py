"""Correspondence search: which detected image lines are which painted court lines.

Image lines are split by direction: *transverse* (within :data:`TRANSVERSE_MAX_DEG` of horizontal: the
court frame puts the camera behind the near baseline) and *longitudinal* (the rest; lines in the band
between both limits are tried as both). A hypothesis pairs two transverse and two longitudinal image lines
with two model lines of each kind in the same order (far before near, left before right — the court frame
has no mirror); their four crossings give a floor → image homography. Hypotheses whose homography admits
no square-pixel camera above the floor on the near side (Zhang's constraints) that sees the court's centre
at least :data:`MIN_ELEVATION_DEG` below the horizon are dropped; the rest are scored on the line-pixel
distance map by how much of the projected court lands on line pixels.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from .lines import ImageLine, LineEvidence, hough_lines
from .model import CourtLines

TRANSVERSE_MAX_DEG = 32.0
LONGITUDINAL_MIN_DEG = 18.0
MAX_LINES_PER_KIND = 10
N_BANDS = 6  # the image is split in this many bands across each kind of line (see _separated)
MAX_PER_BAND = 3  # lines kept per band (see _separated)
MIN_SEPARATION = 0.008  # of the larger image side: closer lines count as one (see _separated)
HIT_PX = 1.5  # working px: a projected model point this close to a line pixel is supported
MISS_WEIGHT = 0.5
FOCAL_RANGE = (0.25, 10.0)  # focal length / larger image side
MIN_ELEVATION_DEG = 5.0  # the camera sees the court's centre at least this far below the horizon
SAMPLE_STEP_M = 0.2
MAX_SAMPLE_PX = 12.0
CHUNK = 4000


@dataclass
class Hypothesis:
    """A floor → full-resolution-pixel homography and its score on the line evidence (lengths in working px)."""

    H: np.ndarray
    score: float
    supported_px: float
    visible_px: float


def find_lines(ev: LineEvidence) -> list[ImageLine]:
    """The image's straight lines (:func:`.lines.hough_lines`), and when fewer than :data:`MAX_LINES_PER_KIND`
    of them run in one of the two directions, the strongest further lines of that direction (a Hough
    transform over those angles only). A broadcast view of a padel court is crossed by many strong transverse
    lines — the walls' rails, the fence's wires, the net, advertising boards, a score box — whose slightly
    tilted copies alone can fill the list, leaving none of the court's longitudinal lines (a real view: 46 of
    48 lines transverse, the centre line and the side walls' bases not among them)."""
    lines = hough_lines(ev)
    for angles in ((0.0, TRANSVERSE_MAX_DEG), (LONGITUDINAL_MIN_DEG, 90.0)):
        have = sum(1 for k in lines if angles[0] <= abs(k.angle_deg) <= angles[1])
        if have < MAX_LINES_PER_KIND:  # as many as the selection (:func:`_separated`) may keep
            lines += hough_lines(ev, 2 * MAX_LINES_PER_KIND - have, angles=angles, kept=lines, depth=40 * 48)
    return lines


def split_lines(lines: list[ImageLine], size: tuple[int, int]) -> tuple[list[ImageLine], list[ImageLine]]:
    """Transverse lines (top of the image first) and longitudinal lines (left first), the strongest of each
    spread over the image (:func:`_separated`)."""
    w, h = size
    by_votes = sorted(lines, key=lambda k: -k.votes)
    y_mid = lambda k: (k.offset - k.normal[0] * w / 2) / k.normal[1]  # noqa: E731  (y at the image's middle)
    x_mid = lambda k: (k.offset - k.normal[1] * h / 2) / k.normal[0]  # noqa: E731
    with np.errstate(divide="ignore", invalid="ignore"):
        trans = _separated([k for k in by_votes if abs(k.angle_deg) <= TRANSVERSE_MAX_DEG], size, y_mid, h)
        longi = _separated([k for k in by_votes if abs(k.angle_deg) >= LONGITUDINAL_MIN_DEG], size, x_mid, w)
    trans.sort(key=lambda k: (k.offset - k.normal[0] * w / 2) / k.normal[1])
    longi.sort(key=lambda k: (k.offset - k.normal[1] * h) / k.normal[0])
    return trans, longi


def _separated(lines: list[ImageLine], size: tuple[int, int], position: Callable[[ImageLine], float],
               extent: float) -> list[ImageLine]:
    """Lines in two passes: the strongest line of each of :data:`N_BANDS` bands of ``position`` (the image
    split across the lines' direction, so weak far lines are kept) and then the rest by votes, up to
    :data:`MAX_LINES_PER_KIND`; then the lines the same selection adds when it keeps at most
    :data:`MAX_PER_BAND` per band (the many strong lines of a fence's mesh in one band must not crowd out
    the court's weaker lines elsewhere) — at most twice :data:`MAX_LINES_PER_KIND` in all. A line within
    :data:`MIN_SEPARATION` × the larger image side of a kept one (median over the image) is skipped: a
    fence's mesh or a thick rail gives many near-duplicates."""
    w, h = size
    probes = np.stack(np.meshgrid(np.linspace(0, w, 5), np.linspace(0, h, 5)), -1).reshape(-1, 2)
    sep = MIN_SEPARATION * max(w, h)

    def distinct(k: ImageLine, kept: list[ImageLine]) -> bool:
        on_k = probes - np.outer(probes @ k.normal - k.offset, k.normal)  # probes moved onto k
        inside = on_k[(on_k >= 0).all(1) & (on_k[:, 0] <= w) & (on_k[:, 1] <= h)]
        return not (len(inside) and any(np.median(o.distance(inside)) < sep for o in kept))

    def band(k: ImageLine) -> int:
        return int(np.clip(position(k) / extent * N_BANDS, 0, N_BANDS - 1)) if np.isfinite(position(k)) else -1

    def select(cap: int | None) -> list[ImageLine]:
        kept: list[ImageLine] = []
        per_band: dict[int, int] = {}
        for k in lines:  # pass 1: the strongest line per band
            if band(k) not in per_band and distinct(k, kept):
                per_band[band(k)] = 1
                kept.append(k)
        del kept[MAX_LINES_PER_KIND:]
        for k in lines:  # pass 2: by votes (at most ``cap`` per band)
            if len(kept) >= MAX_LINES_PER_KIND:
                break
            b = band(k)
            if all(k is not o for o in kept) and (cap is None or per_band.get(b, 0) < cap) and distinct(k, kept):
                per_band[b] = per_band.get(b, 0) + 1
                kept.append(k)
        return kept

    by_votes = select(None)
    spread = select(MAX_PER_BAND)  # a fence's mesh can fill one band with strong lines
    return by_votes + [k for k in spread if all(k is not o for o in by_votes)]


def _batch_homography(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 4, 2) → (M, 4, 2) point quadruples → (M, 3, 3) homographies with H[2, 2] = 1 and a (M,) mask of
    the well-conditioned ones."""
    m = len(src)
    A = np.zeros((m, 8, 8))
    b = np.zeros((m, 8))
    x, y = src[..., 0], src[..., 1]
    u, v = dst[..., 0], dst[..., 1]
    A[:, 0::2, 0], A[:, 0::2, 1], A[:, 0::2, 2] = x, y, 1
    A[:, 0::2, 6], A[:, 0::2, 7] = -u * x, -u * y
    A[:, 1::2, 3], A[:, 1::2, 4], A[:, 1::2, 5] = x, y, 1
    A[:, 1::2, 6], A[:, 1::2, 7] = -v * x, -v * y
    b[:, 0::2], b[:, 1::2] = u, v
    ok = np.abs(np.linalg.det(A)) > 1e-9
    H = np.zeros((m, 3, 3))
    if ok.any():
        h = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
        H[ok] = np.concatenate([h, np.ones((len(h), 1))], axis=1).reshape(-1, 3, 3)
    return H, ok


def _plausible(Hn: np.ndarray, centre_xy: np.ndarray, net_y: float, t_model: np.ndarray) -> np.ndarray:
    """(M,) whether a square-pixel camera with its principal point at the centre explains each normalised
    homography (image coordinates centred and divided by ``scale``): a positive focal length in range from
    Zhang's constraints, the camera above the floor and on the near side of the net."""
    H = Hn @ t_model  # floor metres → normalised image
    a1, b1, c1 = H[:, 0, 0], H[:, 1, 0], H[:, 2, 0]
    a2, b2, c2 = H[:, 0, 1], H[:, 1, 1], H[:, 2, 1]
    A = np.stack([a1 * a2 + b1 * b2, a1 * a1 + b1 * b1 - a2 * a2 - b2 * b2], axis=1)
    B = np.stack([c1 * c2, c1 * c1 - c2 * c2], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = -np.sum(A * B, axis=1) / np.sum(A * A, axis=1)
        f = 1.0 / np.sqrt(np.where(w > 0, w, np.nan))
    ok = np.isfinite(f) & (f > FOCAL_RANGE[0]) & (f < FOCAL_RANGE[1])
    f = np.where(ok, f, 1.0)
    Kinv = np.zeros((len(H), 3, 3))
    Kinv[:, 0, 0] = Kinv[:, 1, 1] = 1.0 / f
    Kinv[:, 2, 2] = 1.0
    M = Kinv @ H
    lam = 2.0 / (np.linalg.norm(M[:, :, 0], axis=1) + np.linalg.norm(M[:, :, 1], axis=1))
    lam = lam * np.sign(M[:, 2, :] @ np.array([centre_xy[0], centre_xy[1], 1.0]))
    r1, r2, t = (M[:, :, k] * lam[:, None] for k in range(3))
    r3 = np.cross(r1, r2)
    C = -np.stack([np.sum(r1 * t, 1), np.sum(r2 * t, 1), np.sum(r3 * t, 1)], axis=1)
    return ok & (C[:, 2] > 0.5) & (C[:, 1] < net_y) & (elevation_deg(C, centre_xy) >= MIN_ELEVATION_DEG)


def elevation_deg(C: np.ndarray, centre_xy: np.ndarray) -> np.ndarray:
    """(..., 3) camera centres → (...) the angle (degrees) below the horizon at which each sees the floor
    point ``centre_xy`` (the court's centre). Under :data:`MIN_ELEVATION_DEG` a camera sees the floor so
    obliquely that the court's depth shrinks more than tenfold in the image: such a placement lays the court
    on upright structure (a wall's rails and posts) seen edge-on, not on the floor."""
    C = np.asarray(C, float)
    return np.degrees(np.arctan2(C[..., 2], np.hypot(C[..., 0] - centre_xy[0], C[..., 1] - centre_xy[1])))


def hypotheses(trans: list[ImageLine], longi: list[ImageLine], model: CourtLines, size: tuple[int, int],
               net_y: float) -> np.ndarray:
    """(M, 3, 3) plausible floor → full-resolution-pixel homographies from ordered line correspondences."""
    if len(trans) < 2 or len(longi) < 2:
        return np.zeros((0, 3, 3))
    w, h = size
    s = float(max(w, h))
    # crossings of every transverse with every longitudinal image line, normalised image coordinates
    X = np.cross(np.array([k.homogeneous for k in trans])[:, None, :],
                 np.array([k.homogeneous for k in longi])[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        X = X[..., :2] / X[..., 2:3]
    X = (X - [w / 2, h / 2]) / s
    combos = np.array([(i, j, k, l, a, b, c, d)
                       for i, j in combinations(range(len(trans)), 2)
                       for k, l in combinations(range(len(longi)), 2)
                       for a, b in combinations(range(len(model.transverse)), 2)
                       for c, d in combinations(range(len(model.longitudinal)), 2)])
    i, j, k, l, a, b, c, d = combos.T
    img = np.stack([X[i, k], X[i, l], X[j, k], X[j, l]], axis=1)
    ty = np.array([m.value for m in model.transverse])
    lx = np.array([m.value for m in model.longitudinal])
    mod = np.stack([np.stack([lx[c], ty[a]], 1), np.stack([lx[d], ty[a]], 1),
                    np.stack([lx[c], ty[b]], 1), np.stack([lx[d], ty[b]], 1)], axis=1)
    finite = np.isfinite(img).all(axis=(1, 2)) & (np.abs(img) < 5).all(axis=(1, 2))
    img, mod = img[finite], mod[finite]
    centre = model.segments.reshape(-1, 2).mean(axis=0)
    span = float(np.ptp(model.segments.reshape(-1, 2), axis=0).max())
    t_model = np.array([[1 / span, 0, -centre[0] / span], [0, 1 / span, -centre[1] / span], [0, 0, 1.0]])
    mod_n = (mod - centre) / span
    Hn, ok = _batch_homography(mod_n, img)
    Hn = Hn[ok]
    Hn = Hn[_plausible(Hn, centre, net_y, t_model)]
    to_px = np.array([[s, 0, w / 2], [0, s, h / 2], [0, 0, 1.0]])
    return to_px @ Hn @ t_model


def score(Hs: np.ndarray, ev: LineEvidence, samples: np.ndarray, seg: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Supported length, visible length (working px) and score (supported − :data:`MISS_WEIGHT` ×
    unsupported) of each homography (M, 3, 3) for floor sample points (P, 2) along segments ``seg`` (P,).

    Each sample stands for the image length between it and the next sample of its segment (at most
    :data:`MAX_SAMPLE_PX`), so a hypothesis is credited with the image length of painted line it explains:
    squeezing the whole court into a small, busy part of the image earns little.
    """
    dist = ev.distance
    hh, ww = dist.shape
    ph = np.concatenate([samples, np.ones((len(samples), 1))], axis=1)
    same = np.append(seg[1:] == seg[:-1], False)
    hit_len = np.zeros(len(Hs))
    vis_len = np.zeros(len(Hs))
    for lo in range(0, len(Hs), CHUNK):
        H = Hs[lo : lo + CHUNK]
        # (m, P) image coordinates, each row of H applied on its own (no (m, P, 3) array and no reductions over
        # a length-2 axis: 1.4x faster on the ~80,000 guesses of a tennis view; scores change by < 1e-11)
        z = H[:, 2:3, 0] * ph[None, :, 0] + H[:, 2:3, 1] * ph[None, :, 1] + H[:, 2:3, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = ((H[:, 0:1, 0] * ph[None, :, 0] + H[:, 0:1, 1] * ph[None, :, 1] + H[:, 0:1, 2]) / z + 0.5) \
                * ev.scale - 0.5
            y = ((H[:, 1:2, 0] * ph[None, :, 0] + H[:, 1:2, 1] * ph[None, :, 1] + H[:, 1:2, 2]) / z + 0.5) \
                * ev.scale - 0.5
            dx, dy = np.diff(x, axis=1, append=x[:, -1:]), np.diff(y, axis=1, append=y[:, -1:])
            step = np.sqrt(dx * dx + dy * dy)
        wgt = np.where(same[None] & np.isfinite(step), np.minimum(step, MAX_SAMPLE_PX), 0.0)
        xi, yi = np.round(x), np.round(y)
        inside = (z > 0) & (xi >= 0) & (xi < ww) & (yi >= 0) & (yi < hh)
        d = np.full(z.shape, np.inf, dtype=np.float32)
        d[inside] = dist[yi[inside].astype(int), xi[inside].astype(int)]
        hit_len[lo : lo + CHUNK] = np.sum(wgt * (d <= HIT_PX), axis=1)
        vis_len[lo : lo + CHUNK] = np.sum(wgt * inside, axis=1)
    return hit_len, vis_len, hit_len - MISS_WEIGHT * (vis_len - hit_len)


def best_hypotheses(Hs: np.ndarray, ev: LineEvidence, model: CourtLines, n: int = 6) -> list[Hypothesis]:
    """The ``n`` best-scoring homographies that differ (projected court corners ≥ 6 working px apart)."""
    if not len(Hs):
        return []
    samples, seg = model.samples(SAMPLE_STEP_M)
    hits, vis, sc = score(Hs, ev, samples, seg)
    corners = np.concatenate([model.crossings(), np.ones((len(model.crossings()), 1))], axis=1)
    out: list[Hypothesis] = []
    kept: list[np.ndarray] = []
    for idx in np.argsort(-sc):
        P = corners @ Hs[idx].T
        px = P[:, :2] / P[:, 2:3] * ev.scale
        if any(np.nanmedian(np.linalg.norm(px - q, axis=1)) < 6.0 for q in kept):
            continue
        kept.append(px)
        out.append(Hypothesis(Hs[idx], float(sc[idx]), float(hits[idx]), float(vis[idx])))
        if len(out) >= n:
            break
    return out
