"""A small, fully known synthetic clip: one shot drawn over a rendered court from a known camera.

It is the embedded sample of ``datasets/sample/`` (regenerate it with
``python -m training.sample_clip datasets/sample/padel_sample``) and a fixture for tests that need a
real clip folder. The full rally generator (players, glass reflections, blur, many shots) builds on the
same clip format; this maker only needs courts, cameras and clip I/O.

What it writes (shared/docs/formats.md): clip.yaml, video.mp4 (mp4v), ball.csv, events.csv,
court_points.csv (the visible named points, projected and perturbed by uniform ±``click_noise_px``
like a careful annotator's clicks), and gt/camera.yaml, gt/ball_3d.csv, gt/events.csv.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from inference.camera import Camera
from inference.clipio import Ball3D, BallTrack, Clip, ClipInfo, CourtPoints, HitEvents, write_video
from inference.court import Court, load_court

LINE_COLOURS = {"paint": (245, 245, 245), "net": (230, 230, 230), "glass": (150, 200, 210), "mesh": (90, 90, 90)}
FLOOR_COLOUR = {"padel": (40, 90, 170), "tennis": (60, 120, 70)}
BALL_COLOUR = (215, 235, 60)


@dataclass
class SampleSpec:
    """What to make. Defaults: the typical installed padel camera, 6 m high, 3 m behind the near glass."""

    sport: str = "padel"
    width: int = 1280
    height: int = 720
    fps: float = 30.0
    n_frames: int = 60
    camera_eye: tuple[float, float, float] = (5.0, -3.0, 6.0)
    camera_target: tuple[float, float, float] = (5.0, 9.0, 0.0)
    fov_deg: float = 80.0
    launch: tuple[float, float, float] = (3.5, 2.0, 1.0)
    velocity: tuple[float, float, float] = (1.2, 14.0, 4.0)
    click_noise_px: float = 1.0
    seed: int = 0


def simulate_shot(court: Court, p0: np.ndarray, v0: np.ndarray, times: np.ndarray, substeps: int = 20):
    """Gravity + quadratic drag with floor bounces (restitution, friction-free spin-less slide).

    Args:
        p0, v0: (3,) launch position (m) and velocity (m/s) at ``times[0]``.
        times: (T,) sample times, increasing.
    Returns:
        positions (T, 3), segment index (T,), bounce times (list of float).
    """
    g = np.array([0.0, 0.0, -court.ball.gravity])
    k = court.ball.drag_k
    e = court.materials[court.planes_for("ground")[0].material].restitution
    r = court.ball.radius
    p, v, t = p0.astype(float).copy(), v0.astype(float).copy(), float(times[0])
    out, seg, bounces, s = [p.copy()], [0], [], 0
    for t_next in times[1:]:
        h = (t_next - t) / substeps
        for _ in range(substeps):
            acc = lambda vel: g - k * np.linalg.norm(vel) * vel  # noqa: E731
            k1v = acc(v)
            k2v = acc(v + 0.5 * h * k1v)
            k3v = acc(v + 0.5 * h * k2v)
            k4v = acc(v + h * k3v)
            p_new = p + h * (v + h / 6 * (k1v + k2v + k3v))
            v_new = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            if p_new[2] < r and v_new[2] < 0:  # floor contact inside this substep
                frac = (p[2] - r) / max(p[2] - p_new[2], 1e-12)
                bounces.append(t + frac * h)
                p_new = p + frac * (p_new - p)
                p_new[2] = r
                v_new = np.array([v_new[0] * 0.85, v_new[1] * 0.85, -v_new[2] * e])
                s += 1
            p, v, t = p_new, v_new, t + h
        out.append(p.copy())
        seg.append(s)
    return np.array(out), np.array(seg), bounces


def render_court(court: Court, cam: Camera, sport: str) -> np.ndarray:
    """(H, W, 3) RGB image of the empty court seen by ``cam``."""
    w, h = cam.image_size
    img = np.full((h, w, 3), (70, 75, 80), np.uint8)
    floor = court.planes_for("ground")[0]
    poly = cam.project(floor.corners_3d())
    cv2.fillPoly(img, [np.round(poly * 16).astype(np.int32)], FLOOR_COLOUR.get(sport, (60, 110, 60)),
                 lineType=cv2.LINE_AA, shift=4)
    for layer, segs in court.lines.items():
        colour = LINE_COLOURS.get(layer, (200, 200, 200))
        for a, b in cam.project(segs.reshape(-1, 3)).reshape(-1, 2, 2):
            if np.isfinite(a).all() and np.isfinite(b).all():
                cv2.line(img, tuple(np.round(a * 16).astype(int)), tuple(np.round(b * 16).astype(int)),
                         colour, 2, cv2.LINE_AA, shift=4)
    return img


def draw_ball(img: np.ndarray, centre_px: np.ndarray, radius_px: float) -> None:
    r = max(radius_px, 1.5)
    cv2.circle(img, tuple(np.round(centre_px * 16).astype(int)), int(round(r * 16)), BALL_COLOUR, -1,
               cv2.LINE_AA, shift=4)


def make_sample_clip(out: str | Path, spec: SampleSpec | None = None) -> Clip:
    """Write a synthetic clip folder with full ground truth; returns the :class:`Clip`."""
    spec = spec or SampleSpec()
    rng = np.random.default_rng(spec.seed)
    court = load_court(spec.sport)
    size = (spec.width, spec.height)
    cam = Camera.from_look_at(spec.camera_eye, spec.camera_target, size, fov_deg=spec.fov_deg)
    cam.source = "ground_truth"
    times = np.arange(spec.n_frames) / spec.fps
    pos, seg, bounces = simulate_shot(court, np.array(spec.launch), np.array(spec.velocity), times)

    px = cam.project(pos)
    inside = np.isfinite(px).all(1) & (px[:, 0] >= 0) & (px[:, 0] < spec.width) & (px[:, 1] >= 0) & (
        px[:, 1] < spec.height)
    vis = inside.astype(np.int8)
    xy = np.where(inside[:, None], px / size, np.nan)
    frames = np.arange(spec.n_frames)
    ev_frames = [0] + [int(round(b * spec.fps)) for b in bounces]
    events = HitEvents(frame=ev_frames, event=["player_near"] + ["ground"] * len(bounces))

    clip = Clip.create(out, ClipInfo(sport=spec.sport, fps=spec.fps, width=spec.width, height=spec.height,
                                     video="video.mp4", n_frames=spec.n_frames, camera_id="installed_back",
                                     split="sample", source="rally3d synthetic sample (training.sample_clip)",
                                     licence="CC0-1.0"), exist_ok=True)
    background = render_court(court, cam, spec.sport)
    f = cam.K[0, 0]
    depth = cam.depth(pos)

    def frames_iter():
        for i in frames:
            img = background.copy()
            if inside[i]:
                draw_ball(img, px[i], f * court.ball.radius / depth[i])
            noise = rng.normal(0, 2.0, img.shape)
            yield np.clip(img + noise, 0, 255).astype(np.uint8)

    write_video(clip.video_path, frames_iter(), spec.fps)
    clip.write_ball(BallTrack(frames, vis, xy))
    clip.write_events(events)
    clip.write_events(events, gt=True)
    names = court.point_names
    cpx = cam.project(court.point_array(names))
    ok = np.isfinite(cpx).all(1) & (cpx[:, 0] >= 0) & (cpx[:, 0] < spec.width) & (cpx[:, 1] >= 0) & (
        cpx[:, 1] < spec.height)
    clicked = cpx[ok] + rng.uniform(-spec.click_noise_px, spec.click_noise_px, (int(ok.sum()), 2))
    clip.write_court_points(CourtPoints([n for n, k in zip(names, ok) if k], np.clip(clicked / size, 0, 1)))
    clip.write_camera(cam, gt=True)
    clip.write_ball_3d(Ball3D(frame=frames, xyz=pos, segment=seg, kind=["gt"] * len(frames)), gt=True)
    return clip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="clip folder to write")
    ap.add_argument("--sport", default="padel")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    clip = make_sample_clip(a.out, SampleSpec(sport=a.sport, n_frames=a.frames, seed=a.seed))
    print(f"wrote {clip.root}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
