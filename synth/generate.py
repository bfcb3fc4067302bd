"""Synthetic clips and datasets: simulate a rally, articulate the players, render, write a clip folder.

One seed fixes everything: the camera, the look, the rally, the bodies and the sensor noise each draw
from their own child stream of ``np.random.SeedSequence(seed)``, so the same seed gives identical files.

Example:
    >>> clip = generate_clip("out/clip_0000", seed=0, config=SynthConfig(sport="padel"))
    >>> manifest = generate_dataset("out", n_clips=20, seed=0, config=SynthConfig(sport="padel"))
"""
from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from inference.camera import Camera
from inference.clipio import (BallTrack, Clip, ClipInfo, Manifest, ManifestEntry, PlayerTracks, atomic_write_text,
                              write_video)
from inference.clipio.frames import write_frames_folder
from inference.court import Court, load_court
from inference.players.skeleton import COCO17

from .partial import PARTIAL, read_marker

from .bodies import PlayerPose, articulate
from .cameras import CameraSpec
from .groundtruth import ball_3d_table, court_point_table, event_table, inactive_ball_table
from .rally import REAL_AROUND, default_config, simulate_rally
from .render import Appearance, CourtRenderer, FrameInfo, ball_exposure
from .types import Rally

CODECS = ("h264", "mp4v", "frames")
VENUES = ("club", "tour")
DEFAULT_CAMERA = {"padel": "padel_installed", "tennis": "tennis_broadcast"}


@dataclass
class SynthConfig:
    """What to generate.

    Attributes:
        sport: ``padel`` or ``tennis`` (the court YAML of that name; or ``court`` gives a path).
        camera: camera preset (default: the sport's usual view); ``randomise_camera`` jitters it and
            draws resolution, fps and lens distortion.
        fps, width, height: fix these instead of drawing them.
        randomise_look: random surfaces, lighting, players, noise, JPEG; else the clean test look.
        codec: ``h264`` (PyAV, realistic compression), ``mp4v`` (OpenCV, fast) or ``frames`` (JPEG folder).
        crf: H.264 quality.
        click_noise_px: uniform noise on court_points.csv (the true projections are in gt/camera.yaml).
        max_frames: cut long rallies to this many frames (None: keep all).
        look_shift: draw the look from another distribution (:meth:`Appearance.shifted`), e.g. a stand-in
            for real footage in fine-tuning benchmarks; the default looks are unchanged.
        around_point: the server's bounces before the serve and the ball after the point (rolling,
            caught, knocked to the side), as real clips hold them; they are not events, and
            ``gt/rally.yaml`` marks the point. Off by default (the default clips are unchanged).
        venue: ``club`` (the default look) or ``tour`` (padel: a tour event as broadcast,
            :meth:`Appearance.tour`: bright rails and posts, the court's outline unpainted, floor logos, a
            score box, an advertising board that may hide the near baseline), drawn from its own stream: the
            other draws are unchanged.
        mid_rally: cut the clip's start inside the rally, as a broadcast's or a highlight's clip often is:
            it opens in the middle of a flight between two racket hits after the serve (the second and third
            hits, or the first and second of a short rally), drawn from its own stream; the serve and what
            came before are not in the clip, no ``gt/rally.yaml`` is written. Off by default.
    """

    sport: str = "padel"
    court: str | None = None
    camera: str | None = None
    randomise_camera: bool = True
    fps: float | None = None
    width: int | None = None
    height: int | None = None
    randomise_look: bool = True
    codec: str = "h264"
    crf: int = 23
    click_noise_px: float = 1.0
    max_frames: int | None = None
    look_shift: bool = False
    around_point: bool = False
    venue: str = "club"
    mid_rally: bool = False

    def __post_init__(self) -> None:
        if self.codec not in CODECS:
            raise ValueError(f"codec must be one of {CODECS}, got {self.codec!r}")
        if self.venue not in VENUES:
            raise ValueError(f"venue must be one of {VENUES}, got {self.venue!r}")


@dataclass
class ClipSummary:
    """What one generated clip holds (one row of the dataset report)."""

    path: str
    seed: int
    n_frames: int
    fps: float
    size: tuple[int, int]
    n_events: int
    outcome: str
    visibility_counts: dict[int, int] = field(default_factory=dict)


def camera_spec(config: SynthConfig, rng: np.random.Generator) -> CameraSpec:
    spec = CameraSpec.preset(config.camera or DEFAULT_CAMERA.get(config.sport, "padel_installed"))
    if config.randomise_camera:
        spec = spec.randomised(rng)
    over = {k: v for k, v in (("fps", config.fps), ("width", config.width), ("height", config.height)) if v}
    return replace(spec, **over) if over else spec


def ball_track(infos: list[FrameInfo], size: tuple[int, int]) -> BallTrack:
    """ball.csv from the renderer's per-frame ball info (every frame gets a row: 0 when no ball)."""
    n = len(infos)
    vis = np.zeros(n, np.int8)
    xy = np.full((n, 2), np.nan)
    for i, info in enumerate(infos):
        if info.ball is not None and info.ball.visibility > 0:
            vis[i] = info.ball.visibility
            xy[i] = np.clip([info.ball.x / size[0], info.ball.y / size[1]], 0.0, 1.0)
    return BallTrack(np.arange(n), vis, xy)


def player_tracks(infos: list[FrameInfo], poses: list[PlayerPose], size: tuple[int, int]) -> PlayerTracks:
    """gt/players.csv: 2D keypoints (visibility as score: 1 visible, 0.5 hidden, 0 outside), boxes,
    the court position (the floor point under the ankles' midpoint) and the 3D joints."""
    rows = {k: [] for k in ("frame", "pid", "team", "bbox", "kp", "court", "j3d")}
    wh = np.asarray(size, float)
    ankles = [COCO17.index("left_ankle"), COCO17.index("right_ankle")]
    for f, info in enumerate(infos):
        for p, pose in zip(info.players, poses):
            rows["frame"].append(f)
            rows["pid"].append(p.player_id)
            rows["team"].append(p.team)
            rows["bbox"].append(np.asarray(p.bbox, float) / np.tile(wh, 2) if p.bbox else np.full(4, np.nan))
            kp = np.concatenate([p.keypoints / wh, (np.asarray(p.keypoint_vis, float) / 2.0)[:, None]], axis=1)
            rows["kp"].append(kp)
            j3d = pose.joints[min(f, pose.n_frames - 1)]
            rows["j3d"].append(j3d)
            rows["court"].append(j3d[ankles, :2].mean(axis=0))
    n = len(rows["frame"])
    return PlayerTracks(np.array(rows["frame"], np.int64), np.array(rows["pid"], np.int64), rows["team"],
                        np.ones(n), np.array(rows["bbox"]).reshape(n, 4), np.array(rows["kp"]).reshape(n, 17, 3),
                        np.array(rows["court"]).reshape(n, 2), np.array(rows["j3d"]).reshape(n, 17, 3))


def mid_rally_start(rally: Rally, rng: np.random.Generator) -> int:
    """A frame inside a flight between two racket hits of the point (the 2nd and 3rd, else the 1st and 2nd),
    drawn in its middle 60 %; 0 when the rally has fewer than two hits."""
    hits = [c.t for c in rally.contacts if c.in_rally and c.player is not None]
    if len(hits) < 2:
        return 0
    a, b = (hits[1], hits[2]) if len(hits) >= 3 else (hits[0], hits[1])
    t = a + (b - a) * rng.uniform(0.2, 0.8)
    return int(np.clip(round(t * rally.fps), 0, rally.n_frames - 1))


def _cut_start(rally: Rally, start: int) -> Rally:
    """The rally seen from frame ``start`` on: every time moves by ``-start / fps``; contacts before the new
    start are dropped, the serve is no longer in the clip (``t_serve`` None)."""
    if start <= 0:
        return rally
    dt = start / rally.fps
    tol = 0.5 / rally.fps
    ball = replace(rally.ball, t=rally.ball.t - dt)
    contacts = [replace(c, t=c.t - dt) for c in rally.contacts if c.t - dt >= tol]
    players = [replace(p, t=p.t[start:] - dt, root=np.asarray(p.root)[start:], heading=np.asarray(p.heading)[start:],
                       swings=[replace(s, t_hit=s.t_hit - dt) for s in p.swings]) for p in rally.players]
    inactive = [replace(b, first=b.first - start, last=b.last - start) for b in rally.inactive_balls
                if b.last - start >= 0]
    return replace(rally, n_frames=rally.n_frames - start, ball=ball, contacts=contacts, players=players,
                   inactive_balls=inactive, t_serve=None,
                   t_dead=None if rally.t_dead is None else rally.t_dead - dt)


def _trim(rally: Rally, max_frames: int | None) -> Rally:
    if not max_frames or rally.n_frames <= max_frames:
        return rally
    t_end = (max_frames - 0.5) / rally.fps
    return replace(rally, n_frames=max_frames, contacts=[c for c in rally.contacts if c.t < t_end])


@dataclass
class SynthScene:
    """Everything one seed fixes before rendering: court, camera, look, rally, bodies, renderer.

    Example:
        >>> scene = SynthScene.build(3, SynthConfig(sport="tennis", camera="tennis_high"))
        >>> image = scene.frame(0)        # (H, W, 3) uint8 RGB, exactly as in the clip's video
    """

    court: Court
    spec: CameraSpec
    camera: Camera
    look: Appearance
    rally: Rally
    poses: list[PlayerPose]
    renderer: CourtRenderer
    r_points: np.random.Generator

    @classmethod
    def build(cls, seed: int, config: SynthConfig) -> SynthScene:
        court = load_court(config.court or config.sport)
        seq = np.random.SeedSequence(seed)
        r_cam, r_look, r_rally, r_body, r_points = (np.random.default_rng(s) for s in seq.spawn(5))
        spec = camera_spec(config, r_cam)
        camera = spec.build(court)
        look = Appearance.sample(r_look, config.sport) if config.randomise_look else Appearance.plain(config.sport)
        if config.look_shift:
            look = look.shifted(np.random.default_rng([seed, 7]))  # its own stream: the default draws are unchanged
        if config.venue == "tour":
            look = look.tour(np.random.default_rng([seed, 11]))
        rally_cfg = default_config(config.sport)
        if config.around_point:
            rally_cfg = replace(rally_cfg, around=REAL_AROUND)
        rally = simulate_rally(court, spec.fps, r_rally, sport=config.sport, config=rally_cfg)
        if config.mid_rally:
            rally = _cut_start(rally, mid_rally_start(rally, np.random.default_rng([seed, 13])))
        rally = _trim(rally, config.max_frames)
        poses = [articulate(p, spec.fps, r_body, sport=config.sport) for p in rally.players]
        renderer = CourtRenderer(court, camera, look, seed=int(seq.generate_state(1)[0]))
        return cls(court, spec, camera, look, rally, poses, renderer, r_points)

    def frame(self, i: int) -> tuple[np.ndarray, FrameInfo]:
        """Frame ``i`` (ball, players and inactive balls included) and its ground-truth info."""
        samples = ball_exposure(self.rally.ball, i, self.spec.fps, self.look.shutter)
        return self.renderer.render(i, samples, self.poses, self.rally.inactive_balls)


def generate_clip(out: str | Path, seed: int, config: SynthConfig | None = None,
                  progress: Callable[[int, int], None] | None = None) -> ClipSummary:
    """Simulate and render one clip into the folder ``out`` (created; existing files are replaced).

    Args:
        out: the clip folder.
        seed: fixes camera, look, rally, bodies and noise.
        progress: called as ``progress(frames_done, n_frames)`` while rendering.
    """
    config = config or SynthConfig()
    scene = SynthScene.build(seed, config)
    court, spec, camera, rally, poses = scene.court, scene.spec, scene.camera, scene.rally, scene.poses
    size = camera.image_size

    clip = Clip.create(out, ClipInfo(
        sport=config.sport, fps=spec.fps, width=size[0], height=size[1],
        video="frames/" if config.codec == "frames" else "video.mp4", n_frames=rally.n_frames,
        camera_id=config.camera or DEFAULT_CAMERA.get(config.sport), split=None,
        source=f"rally3d synth seed {seed}", licence="CC0-1.0", court=config.court,
        extra={"synth": {"seed": seed, "outcome": rally.outcome, "camera": _plain(spec.to_dict())}},
    ), exist_ok=True)
    infos: list[FrameInfo] = []

    def frames():
        for i in range(rally.n_frames):
            image, info = scene.frame(i)
            infos.append(info)
            if progress:
                progress(i + 1, rally.n_frames)
            yield image

    if config.codec == "frames":
        write_frames_folder(clip.root / "frames", frames())
    else:
        write_video(clip.video_path, frames(), spec.fps, fourcc=config.codec, crf=config.crf)
    track = ball_track(infos, size)
    clip.write_ball(track)
    clip.write_inactive_balls(inactive_ball_table(rally, camera))
    events = event_table(rally)
    clip.write_events(events)
    clip.write_events(events, gt=True)
    clip.write_court_points(court_point_table(court, camera, scene.r_points, config.click_noise_px))
    clip.write_camera(camera, gt=True)
    clip.write_ball_3d(ball_3d_table(rally), gt=True)
    clip.write_players(player_tracks(infos, poses, size), gt=True)
    if config.around_point and rally.rally_frames() is not None:
        from inference.events.rally import RallySegment, write_rally_yaml

        start, end = rally.rally_frames()
        write_rally_yaml(clip.gt_dir / "rally.yaml", RallySegment(start, end, np.zeros(0, bool), "hit"), spec.fps,
                         [(int(round(c.t * spec.fps)), c.event) for c in rally.contacts if not c.in_rally],
                         source="ground_truth")
    counts = {int(v): int(c) for v, c in zip(*np.unique(track.visibility, return_counts=True))}
    return ClipSummary(str(clip.root), seed, rally.n_frames, spec.fps, size, len(events), rally.outcome, counts)


def _plain(d):
    """YAML-safe copy of a dataclass dict (tuples → lists, numpy → float)."""
    if isinstance(d, dict):
        return {k: _plain(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [_plain(v) for v in d]
    if isinstance(d, np.generic):
        return d.item()
    return d


PARTIAL_DIR = ".partial"
"""The hidden folder a clip is rendered into before it is moved into place, complete."""


def generate_dataset(out: str | Path, n_clips: int, seed: int = 0, config: SynthConfig | None = None,
                     fractions: tuple[float, float, float] = (0.8, 0.1, 0.1),
                     progress: Callable[[int, ClipSummary], None] | None = None) -> Manifest:
    """``n_clips`` clips ``clip_0000 …`` under ``out`` plus ``manifest.yaml`` with train/val/test splits.

    Clip ``k`` uses seed ``seed * 100003 + k``: the dataset is reproducible and its clips independent.
    Splits are assigned in proportion to ``fractions`` over a seeded permutation, so small datasets
    still get every split.

    Never mistaken for a finished dataset when interrupted (Ctrl-C, a crash): the :data:`PARTIAL` marker is
    written first and removed after ``manifest.yaml`` (an earlier manifest is removed at the start); each clip
    is rendered in a hidden folder and moved into place complete. Run again with the same arguments, it
    resumes (the clips made are kept, with a line saying so); with other arguments it makes every clip again.
    """
    config = config or SynthConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    source = f"rally3d synth --sport {config.sport} --clips {n_clips} --seed {seed}"
    plan = _plain({"n_clips": n_clips, "seed": seed, "fractions": list(fractions), "config": asdict(config)})
    done = _resumable(out, plan)
    _mark(out, source, plan, done)
    (out / "manifest.yaml").unlink(missing_ok=True)
    splits = split_assignment(n_clips, fractions, np.random.default_rng(seed))
    entries = []
    for k in range(n_clips):
        name = f"clip_{k:04d}"
        if name not in done:
            done[name] = _plain(asdict(_clip_into_place(out, name, seed * 100003 + k, config, splits[k])))
            _mark(out, source, plan, done)
        entries.append(ManifestEntry(name, splits[k]))
        if progress:
            progress(k + 1, ClipSummary(**{**done[name], "size": tuple(done[name]["size"])}))
    manifest = Manifest(out, entries, name=out.name, sport=config.sport, source=source,
                        extra={"synth_config": _plain(asdict(config))})
    manifest.save()
    (out / PARTIAL).unlink()
    shutil.rmtree(out / PARTIAL_DIR, ignore_errors=True)
    return manifest


def _mark(out: Path, source: str, plan: dict, done: dict[str, dict]) -> None:
    atomic_write_text(out / PARTIAL, yaml.safe_dump({"source": source, "plan": plan, "done": done}, sort_keys=False))


def _resumable(out: Path, plan: dict) -> dict[str, dict]:
    """The clips (name → summary) an interrupted generation of the same ``plan`` made in ``out``, with a
    line saying what is resumed or redone; {} when there is nothing to resume."""
    state = read_marker(out)
    if state is None:
        return {}
    if state.get("plan") != plan:
        print(f"{out}: an interrupted generation with other settings was here: making every clip again", flush=True)
        return {}
    done = {n: s for n, s in (state.get("done") or {}).items() if (out / n / "clip.yaml").is_file()}
    print(f"{out}: resuming an interrupted generation: {len(done)} of {plan['n_clips']} clips already made",
          flush=True)
    return done


def _clip_into_place(out: Path, name: str, seed: int, config: SynthConfig, split: str) -> ClipSummary:
    """Render clip ``name`` in :data:`PARTIAL_DIR`, then move it, complete, to ``out/name`` (replacing it)."""
    tmp, final = out / PARTIAL_DIR / name, out / name
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        summary = generate_clip(tmp, seed, config)
        clip = Clip(tmp)
        clip.write_info(replace(clip.info, split=split))
        if final.exists():
            shutil.rmtree(final)
        os.replace(tmp, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return replace(summary, path=str(final))


def split_assignment(n: int, fractions: tuple[float, float, float], rng: np.random.Generator) -> list[str]:
    """``n`` split names in the given proportions (at least one val and test clip once n ≥ 3)."""
    f = np.asarray(fractions, float) / sum(fractions)
    n_val = max(int(round(n * f[1])), 1 if n >= 3 and f[1] > 0 else 0)
    n_test = max(int(round(n * f[2])), 1 if n >= 3 and f[2] > 0 else 0)
    names = ["val"] * n_val + ["test"] * n_test
    names = ["train"] * (n - len(names)) + names
    return [names[i] for i in rng.permutation(n)]
