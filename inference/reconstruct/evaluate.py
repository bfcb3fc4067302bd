"""Evaluation of 3D reconstruction against ground truth (``gt/ball_3d.csv``), as in the thesis's tables.

Metrics per method over all reconstructed frames that have ground truth:
MRE / MedRE — mean / median reprojection error (px) of the reconstruction against the 2D input;
MAE / MedAE — mean / median 3D error (m) against gt/ball_3d.csv; frames/s — reconstructed frames per
second of compute on this machine; coverage — share of the rally's frames that were reconstructed.

Perturbations for sensitivity studies: Gaussian noise on the 2D input (px) and random shifts of the event
frames (±k frames), both seeded.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.clipio import Clip, HitEvents, PlayerTracks

from .observations import Observations
from .results import RallyFit


@dataclass
class Setting:
    """How the inputs are prepared.

    Attributes:
        noise_px: σ of Gaussian noise added to the 2D ball (px).
        event_shift: events move by a random integer in [-k, k] frames.
        players: ``clip`` (players.csv if present), ``gt`` (gt/players.csv's court positions) or ``none``.
        camera: ``gt`` (gt/camera.yaml), ``clip`` (camera.yaml) or ``clicked`` (calibrated here from the
            clip's court_points.csv — `rally3d synth` draws them ±1 px off — with its pose covariance, as
            `rally3d calibrate` writes it).
        seed: for the noise and shifts.
    """

    noise_px: float = 2.0
    event_shift: int = 0
    players: str = "gt"
    camera: str = "gt"
    seed: int = 0

    def label(self) -> str:
        return f"noise {self.noise_px:g}px, events ±{self.event_shift}, players {self.players}, camera {self.camera}"


@dataclass
class Scores:
    """Accumulated errors of one method."""

    reproj: list[np.ndarray] = field(default_factory=list)
    err3d: list[np.ndarray] = field(default_factory=list)
    frames: int = 0
    total_frames: int = 0
    seconds: float = 0.0
    failed: list[str] = field(default_factory=list)

    def add(self, fit: RallyFit, obs: Observations, gt_frames: np.ndarray, gt_xyz: np.ndarray) -> None:
        b = fit.ball_3d()
        self.total_frames += int(obs.event_frames[-1] - obs.event_frames[0] + 1) if len(obs.event_frames) else 0
        self.seconds += fit.seconds
        self.failed += [f"{obs.source}: segment {s.segment.index}: {s.reason}" for s in fit.segments if not s.ok]
        if not len(b):
            return
        self.frames += len(b)
        self.reproj.append(fit.reprojection_errors(obs.camera, obs.uv))
        i = np.searchsorted(gt_frames, b.frame)
        ok = (i < len(gt_frames)) & (gt_frames[np.minimum(i, len(gt_frames) - 1)] == b.frame)
        self.err3d.append(np.linalg.norm(b.xyz[ok] - gt_xyz[i[ok]], axis=1))

    def row(self) -> dict:
        rep = np.concatenate(self.reproj) if self.reproj else np.zeros(0)
        e3 = np.concatenate(self.err3d) if self.err3d else np.zeros(0)

        def stat(a, f):
            return float(f(a)) if len(a) else float("nan")

        return {"MRE_px": stat(rep, np.mean), "MedRE_px": stat(rep, np.median), "MAE_m": stat(e3, np.mean),
                "MedAE_m": stat(e3, np.median), "fps": self.frames / self.seconds if self.seconds else float("nan"),
                "coverage": self.frames / self.total_frames if self.total_frames else float("nan"),
                "frames": self.frames}


def prepare(clip: Clip, setting: Setting) -> tuple[Observations, np.ndarray, np.ndarray]:
    """The observations of a clip under a setting, and its ground truth (frames (G,), xyz (G, 3))."""
    rng = np.random.default_rng(setting.seed)
    if setting.camera == "clicked":
        camera = clicked_camera(clip)
    else:
        camera = clip.read_camera(gt=setting.camera == "gt")
    events = clip.read_events()
    if setting.event_shift:
        shifted = events.frame + rng.integers(-setting.event_shift, setting.event_shift + 1, len(events))
        shifted = np.clip(shifted, 0, clip.n_frames - 1)
        order = np.argsort(shifted, kind="stable")
        keep = np.concatenate([[True], np.diff(shifted[order]) > 0])   # drop collisions
        events = HitEvents(shifted[order][keep], events.event[order][keep])
    players = None
    if setting.players == "gt":
        players = clip.read_players(gt=True, missing_ok=True)
    elif setting.players == "clip":
        players = clip.read_players(missing_ok=True)
    if players is not None and not len(players):
        players = None
    from inference.court import load_court

    obs = Observations.from_tables(load_court(clip.court_path()), camera, clip.info.fps, clip.read_ball(), events,
                                   clip.n_frames, players, str(clip.root.name))
    if setting.noise_px > 0:
        obs = obs.with_track(obs.uv + rng.normal(0.0, setting.noise_px, obs.uv.shape))
    gt = clip.read_ball_3d(gt=True)
    return obs, gt.frame, gt.xyz


def clicked_camera(clip: Clip):
    """The camera calibrated from the clip's court_points.csv (normalised coordinates) on its court, with the
    calibration's report in its meta (``pose_cov`` among it); with two radial distortion terms when the true
    lens has distortion (as a user calibrating that lens would: `rally3d calibrate --distortion 2`)."""
    from inference.camera.calibration import calibrate_court
    from inference.court import load_court

    true = clip.read_camera(gt=True)
    size = true.image_size
    pts = {n: (float(x) * size[0], float(y) * size[1]) for n, (x, y) in clip.read_court_points().as_dict().items()}
    return calibrate_court(load_court(clip.court_path()), pts, size, n_dist=0 if true.dist is None else 2).camera


def evaluate(clips: list[Clip], methods: dict, setting: Setting) -> dict[str, dict]:
    """Run each method (name → ``fn(obs) -> RallyFit``) on every clip; one metrics row per method."""
    scores = {m: Scores() for m in methods}
    for clip in clips:
        obs, gf, gx = prepare(clip, setting)
        for name, fn in methods.items():
            scores[name].add(fn(obs), obs, gf, gx)
    return {m: {**s.row(), "failed": s.failed} for m, s in scores.items()}


def format_table(rows: dict[str, dict], title: str = "") -> str:
    """A Markdown table like the thesis's Tables 5.6–5.8."""
    lines = [title] if title else []
    lines += ["| method | MRE px | MedRE px | MAE m | MedAE m | frames/s | coverage |",
              "|---|---|---|---|---|---|---|"]
    for m, r in rows.items():
        lines.append(f"| {m} | {r['MRE_px']:.2f} | {r['MedRE_px']:.2f} | {r['MAE_m']:.3f} | {r['MedAE_m']:.3f} | "
                     f"{r['fps']:.0f} | {r['coverage'] * 100:.0f}% |")
    return "\n".join(lines)


#: P(|x| ≤ k) of a 1D standard normal for k = 1, 2: the share of errors within the 1-σ / 2-σ marginal band
GAUSS_1D = (0.6827, 0.9545)


def ray_basis(ray: np.ndarray) -> np.ndarray:
    """(F, 3, 3) orthonormal rows per frame: the line of sight ``ray`` (F, 3), the horizontal direction across
    it, and the third (across, in the vertical plane of the ray)."""
    a = ray / np.linalg.norm(ray, axis=1, keepdims=True)
    h = np.cross(a, np.array([0.0, 0.0, 1.0]))
    n = np.linalg.norm(h, axis=1, keepdims=True)
    h = np.where(n > 1e-9, h / np.maximum(n, 1e-12), np.array([1.0, 0.0, 0.0]))   # a vertical ray: any horizontal
    return np.stack([a, h, np.cross(a, h)], axis=1)


def direction_coverage(d: np.ndarray, cov: np.ndarray, ray: np.ndarray) -> dict[str, tuple[float, float]]:
    """Share of the errors ``d`` (F, 3) within 1 σ and 2 σ of their reported covariance ``cov`` (F, 3, 3),
    per direction: ``along`` the line of sight ``ray`` (F, 3) and ``across`` it (the two directions across
    pooled), each against its marginal σ (√(uᵀ C u)); a calibrated covariance gives :data:`GAUSS_1D` in both.
    Empty input: NaN."""
    if not len(d):
        return {"along": (float("nan"),) * 2, "across": (float("nan"),) * 2}
    E = ray_basis(ray)
    z = np.einsum("fki,fi->fk", E, d) / np.sqrt(np.einsum("fki,fij,fkj->fk", E, cov, E))   # (F, 3) marginal z
    along, across = np.abs(z[:, 0]), np.abs(z[:, 1:]).ravel()
    return {"along": (float(np.mean(along <= 1)), float(np.mean(along <= 2))),
            "across": (float(np.mean(across <= 1)), float(np.mean(across <= 2)))}
