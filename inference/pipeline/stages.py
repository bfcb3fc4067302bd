"""The stages of ``rally3d infer``, each a small function over the clip folder.

Each stage declares the files it reads (its *inputs*, fingerprinted for resuming), its parameters and the
files it writes. A stage that cannot run says why: :class:`Skip` (an optional input is absent — e.g. no
calibration, no pose backend) or :class:`StageError` (bad input: the message names the file and the fix).

Order: camera → scenes → detect → smooth → players → events → reconstruct. The camera comes first because it
is cheap and a calibration that does not fit the video must stop the run before the expensive detection; the
players come before the events so that the player-aware event model can read them (without players, or
with ``--pose none``, it runs on the ball alone). Every stage after ``scenes`` leaves the frames outside its
court-view scenes (``scenes.json``: close-ups, replays between the editor's cuts) out: no ball, player row,
event or 3D point there.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from inference.clipio import BallTrack, Clip
from inference.court import Court

from .state import STATE_DIR, RunState, backup_file


class Skip(Exception):
    """The stage does not apply to this clip (its reason is shown in the summary)."""


class StageError(RuntimeError):
    """The stage failed on bad input; the message names the file and the fix."""


@dataclass
class PipelineConfig:
    """What ``rally3d infer`` runs with.

    Attributes:
        detector: ``wasb``, ``tracknetv2`` or ``monotrack``; detector_weights: checkpoint (None: shipped).
        trust_checkpoint: allow a detector checkpoint that holds pickled objects (runs their code).
        step: detector window step (frames); batch_size: windows per forward pass.
        detector_backend: ``auto`` (ONNX Runtime on the CPU where installed), ``torch``, ``onnx`` or ``onnx-int8``
            (the weights' int8 companion); detector_crop: crop-tracking ``auto`` or ``off``.
        events: hit-event checkpoint (None: the shipped model of the clip's sport).
        rally_only: leave the events judged outside the point (warm-up bounces, the ball after it) out of
            events.csv (rally.yaml lists them either way).
        pose: pose backend (``auto``: MoveNet if installed, ``none``: no players, or a backend name).
        pose_model: model file for the pose backend (None: its default).
        pose_every: pose every N-th frame and let the tracker fill the frames between (0: ``auto``, the
            stride that poses about :data:`~inference.players.sampling.POSE_RATE_HZ` times a second).
        method: 3D reconstruction method.
        device: ``cpu`` or ``cuda[:i]``.
        overwrite: replace files that the pipeline did not write (a backup is kept).
        progress: show progress bars.
        auto_court: without court points or a camera, find the court automatically (its gate may refuse).
    """

    detector: str = "wasb"
    detector_weights: Path | None = None
    trust_checkpoint: bool = False
    step: int = 3
    batch_size: int = 1
    detector_backend: str = "auto"
    detector_crop: str = "auto"
    events: Path | None = None
    rally_only: bool = False
    pose: str = "auto"
    pose_model: Path | None = None
    pose_every: int = 0
    method: str = "joint"
    device: str = "cpu"
    overwrite: bool = False
    progress: bool = True
    auto_court: bool = False  # no court points: fit the court's lines (``--court-points auto``)

    def __post_init__(self) -> None:
        if self.step < 1 or self.batch_size < 1:
            raise ValueError(f"step and batch_size must be ≥ 1, got {self.step}, {self.batch_size}")
        if self.pose_every < 0:
            raise ValueError(f"pose_every must be ≥ 1 (or 0: auto), got {self.pose_every}")
        if self.detector_backend not in ("auto", "torch", "onnx", "onnx-int8") or self.detector_crop not in ("auto", "off"):
            raise ValueError(f"detector_backend must be auto, torch, onnx or onnx-int8 and detector_crop auto or off, got "
                             f"{self.detector_backend!r}, {self.detector_crop!r}")


@dataclass
class Context:
    """What the stages share while one clip runs."""

    clip: Clip
    court: Court
    cfg: PipelineConfig
    state: RunState

    def given_camera(self) -> bool:
        """Whether camera.yaml was supplied by the user (not computed by this pipeline)."""
        path = self.clip.camera_path
        return path.is_file() and not self.state.written_by_pipeline(path)

    @property
    def detected_path(self) -> Path:
        """The detector's raw track (before smoothing), kept so smoothing can be re-run alone."""
        return self.clip.root / STATE_DIR / "ball_detected.csv"


@dataclass
class Outcome:
    """What a stage did: frames it processed (for frames/s) and a note for the summary."""

    frames: int = 0
    note: str = ""
    partial: bool = False  # the stage wrote results but they do not cover the whole clip


@dataclass
class Stage:
    """One step: ``inputs(ctx)`` role → file, ``params(ctx)``, ``outputs(ctx)`` files, ``run(ctx)`` → Outcome."""

    name: str
    inputs: Callable[[Context], dict[str, Path | None]]
    params: Callable[[Context], dict[str, Any]]
    outputs: Callable[[Context], list[Path]]
    run: Callable[[Context], Outcome]
    requires: tuple[str, ...] = ()  # stages whose success this one needs
    code: tuple[str, ...] = ()  # modules whose source is part of the key (a code change re-runs the stage)


# ------------------------------------------------------------------------------------------- camera
def _camera_inputs(ctx: Context) -> dict[str, Path | None]:
    given = ctx.clip.camera_path if ctx.given_camera() else None
    return {"court_points": ctx.clip.court_points_path, "camera": given, "clip_yaml": ctx.clip.clip_yaml_path}


def _camera_run(ctx: Context) -> Outcome:
    from inference.camera.calibration import calibrate_court, require_court_view

    clip = ctx.clip
    if ctx.given_camera():
        clip.check_camera(clip.read_camera())
        require_court_view(clip.read_camera(), ctx.court, clip.camera_path)
        return Outcome(note="camera.yaml given" + _drift_note(ctx))
    if clip.court_points_path.is_file():
        points = clip.read_court_points(known_names=ctx.court.point_names)
        size = np.array([clip.info.width, clip.info.height], dtype=float)
        result = calibrate_court(ctx.court, {n: xy * size for n, xy in zip(points.names, points.xy)},
                                 (clip.info.width, clip.info.height))
        require_court_view(result.camera, ctx.court, clip.court_points_path)
        clip.write_camera(result.camera)
        warn = "".join(f"; warning: {w}" for w in result.warnings)
        return Outcome(note=f"calibrated from {len(result.names)} court points ({result.method}), "
                       f"RMS {result.rms_px:.2f} px{warn}{_drift_note(ctx)}")
    if ctx.cfg.auto_court:
        from inference.courtfit import fit_court

        fit = fit_court(clip, ctx.court)
        if not fit.accepted:
            raise Skip(f"{fit.summary()}; click court points (rally3d label) and pass --court-points "
                       "court_points.csv (3D is skipped)")
        clip.write_camera(fit.camera)
        return Outcome(note=fit.summary() + _drift_note(ctx))
    raise Skip("no calibration: pass --camera camera.yaml, --court-points court_points.csv or --court-points auto "
               "(3D is skipped)")


def _drift_note(ctx: Context) -> str:
    """``; camera drift ...`` when the court moves in the video beyond the calibration (else "")."""
    from inference.clipio import FormatError
    from inference.courtfit.drift import CAMERA_TRACK, measure_drift, track_camera

    track_path = ctx.clip.root / CAMERA_TRACK
    track_path.unlink(missing_ok=True)  # the camera stage owns it: a new calibration drops the old track
    try:
        report = measure_drift(ctx.clip, ctx.clip.read_camera(), ctx.court)
        if not report.drifting:
            return ""
        track, _ = track_camera(ctx.clip, ctx.clip.read_camera(), ctx.court, known=report)  # its frames reused
    except (FormatError, ValueError) as e:  # a drift check never sinks the calibration
        return f"; drift not measured ({e})"
    track.write(track_path)
    return (f"; warning: {report.summary()}; the camera is tracked per frame ({CAMERA_TRACK}, measured at "
            f"{int(track.measured.sum())} frames) and the 3D stage undoes the shift")


def _camera_outputs(ctx: Context) -> list[Path]:
    computed = ctx.clip.court_points_path.is_file() or ctx.cfg.auto_court
    return [] if ctx.given_camera() or not computed else [ctx.clip.camera_path]


# ------------------------------------------------------------------------------------------- scenes
def _scenes_run(ctx: Context) -> Outcome:
    from inference.clipio import FormatError
    from inference.video.scenes import LEGACY_FILE, Scene, SceneReport, find_scenes

    clip = ctx.clip
    # a folder from before scenes.json had its name: its old file is replaced, unless made by hand (kept, as
    # every file the pipeline did not write)
    legacy = clip.root / LEGACY_FILE
    if legacy.is_file() and not ctx.state.written_by_pipeline(legacy):
        if not ctx.cfg.overwrite:
            raise StageError(f"{legacy} (the former name of scenes.json) was not written by rally3d infer — "
                             "rename it scenes.json to keep it, or pass --overwrite to replace it (a backup is "
                             f"kept in {STATE_DIR}/backup/)")
        backup_file(clip.root, legacy)
    camera = clip.read_camera() if clip.camera_path.is_file() else None
    try:
        report = find_scenes(clip, camera, ctx.court, progress=ctx.cfg.progress)
    except FormatError as e:  # a damaged video: no cut search, every frame goes on (detect keeps what decodes)
        report = SceneReport([Scene(0, clip.n_frames, True, 0.0, "not measured")], clip.n_frames, clip.info.fps,
                             [f"scenes not measured ({e}); every frame is searched"])
    if len(report.scenes) > 1 or report.notes:
        print("[scenes]\n" + report.table())  # the terminal's view of scenes.json
    report.write(_scenes_output(ctx))
    legacy.unlink(missing_ok=True)
    return Outcome(report.n_frames, report.summary())


def _scenes_output(ctx: Context) -> Path:
    """scenes.json, what the scenes stage writes."""
    from inference.video.scenes import SCENES_FILE

    return ctx.clip.root / SCENES_FILE


def _scenes_path(ctx: Context) -> Path:
    """The scenes file the later stages read: scenes.json (in a folder from before that name, with only the
    old file, that one: :func:`inference.video.scenes.scenes_file`)."""
    from inference.video.scenes import scenes_file

    return scenes_file(ctx.clip.root)


def _court_frames(ctx: Context) -> np.ndarray | None:
    """(N,) bool court-view frames from scenes.json (None: no scenes.json, every frame is processed)."""
    from inference.video.scenes import SceneReport

    if not _scenes_path(ctx).is_file():
        return None
    report = SceneReport.read(_scenes_path(ctx))
    if report.n_frames != ctx.clip.n_frames:
        raise StageError(f"{_scenes_path(ctx)} describes {report.n_frames} frames, the video has "
                         f"{ctx.clip.n_frames} — delete it and re-run (the scenes stage rewrites it)")
    return report.active()


def _cut_frames(ctx: Context) -> list[int]:
    """The first frame of every scene after the first (scenes.json; [] without it): no flight is smoothed
    across a cut."""
    from inference.video.scenes import SceneReport

    if _court_frames(ctx) is None:
        return []
    return [s.start for s in SceneReport.read(_scenes_path(ctx)).scenes[1:]]


def _court_spans(ctx: Context) -> list[tuple[int, int]] | None:
    """The court-view scenes ``[(start, stop), ...]`` that the events and 3D stages handle one by one (None: no
    scenes.json or a single view of the whole clip — the clip is handled whole, as without scenes)."""
    from inference.video.scenes import SceneReport

    if _court_frames(ctx) is None:
        return None
    spans = SceneReport.read(_scenes_path(ctx)).court_spans()
    return None if spans == [(0, ctx.clip.n_frames)] else spans


# ------------------------------------------------------------------------------------------- detect
def _weights_path(ctx: Context) -> Path:
    from inference.detection.detect import shipped_weights

    w = ctx.cfg.detector_weights or shipped_weights(ctx.cfg.detector, ctx.clip.info.sport)[0]
    if w is None:
        raise StageError(f"no shipped weights for the {ctx.cfg.detector} detector: pass --detector CKPT")
    w = Path(w)
    if not w.is_file():
        raise StageError(f"{w}: detector weights not found — pass the path of a checkpoint with --detector "
                         "(weights are never downloaded)")
    return w


def _detect_run(ctx: Context) -> Outcome:
    from inference.clipio import write_ball_csv
    from inference.detection.crop import crop_config
    from inference.detection.detect import BallDetectorRunner

    runner = BallDetectorRunner.from_weights(ctx.cfg.detector, _weights_path(ctx), trust=ctx.cfg.trust_checkpoint,
                                             step=ctx.cfg.step, batch_size=ctx.cfg.batch_size, device=ctx.cfg.device,
                                             backend=ctx.cfg.detector_backend,
                                             crop=crop_config(ctx.cfg.detector_crop))
    active = _court_frames(ctx)
    result = runner.run(ctx.clip, progress=ctx.cfg.progress, tolerate_truncation=True, active=active)
    ctx.detected_path.parent.mkdir(parents=True, exist_ok=True)
    write_ball_csv(ctx.detected_path, result.track)
    seen = int(np.sum(result.track.visibility > 0))
    note = f"ball in {seen}/{result.n_frames} frames ({runner.engine.name})"   # which network ran
    if active is not None and not active.all():
        note += f" ({int((~active).sum())} frames outside court views not searched, {_scenes_path(ctx).name})"
    if ctx.cfg.detector_weights is None:
        from inference.detection.detect import SHIPPED_SPORT, shipped_weights

        if SHIPPED_SPORT.get(ctx.cfg.detector) != ctx.clip.info.sport:
            note += "; warning: " + shipped_weights(ctx.cfg.detector, ctx.clip.info.sport)[1]
    if result.truncated:
        return Outcome(result.n_frames, f"{note}; video truncated: {result.truncated}", partial=True)
    if seen == 0:
        raise StageError(f"{ctx.clip.video_path}: no ball detected in any of {result.n_frames} frames — check "
                         "the video shows a rally, or pass other --detector weights")
    return Outcome(result.n_frames, note)


# ------------------------------------------------------------------------------------------- smooth
def _smooth_run(ctx: Context) -> Outcome:
    from inference.clipio import read_ball_csv
    from inference.detection.smooth import smooth_track

    raw = read_ball_csv(ctx.detected_path)
    info = ctx.clip.info
    # the tracker's coasts (visibility 3) are its own predictions, wrong across every bounce and hit: only
    # detections are measurements
    coasted = raw.visibility == 3
    xy = raw.xy.copy()
    xy[coasted] = np.nan
    vis = np.where(coasted, 0, raw.visibility)
    active = _court_frames(ctx)
    if active is not None:  # a detection outside the court views (a track made elsewhere) is no ball of ours
        off = (raw.frame >= 0) & (raw.frame < len(active))
        off[off] = ~active[raw.frame[off]]
        vis[off], xy[off] = 0, np.nan
    measured = BallTrack(raw.frame, vis, xy)
    res = smooth_track(measured, info.width, info.height, info.fps, event_frames=_cut_frames(ctx))
    ctx.clip.write_ball(res.track)
    return Outcome(len(raw), f"{len(res.pieces)} pieces, {int(coasted.sum())} coasted frames and "
                   f"{len(res.outliers)} outliers dropped")


# ------------------------------------------------------------------------------------------- events
def _events_run(ctx: Context) -> Outcome:
    try:
        from inference.events import EventDetector
    except ImportError as e:  # pragma: no cover - the package ships with inference
        raise StageError(f"the hit-event model is unavailable ({e})") from e
    clip = ctx.clip
    camera = clip.read_camera() if clip.camera_path.is_file() else None
    players = _players_for_events(ctx)
    if ctx.cfg.events is not None and not Path(ctx.cfg.events).is_file():
        raise StageError(f"{ctx.cfg.events}: hit-event checkpoint not found — pass an existing file with --events")
    det = EventDetector.from_checkpoint(_events_weights(ctx), sport=clip.info.sport)
    frames = clip.frames(cache_size=16)
    spans = _court_spans(ctx)
    try:
        pl = players if det.wants_players else None
        if spans is None:
            result = det.predict(clip.read_ball(), clip.info.fps, clip.info.width, clip.info.height, camera=camera,
                                 players=pl, frames=frames, keep_all=not ctx.cfg.rally_only)
        else:  # a broadcast clip: each court-view scene on its own, no event window across a cut
            from .per_scene import events_per_scene

            result = events_per_scene(det, clip.read_ball(), spans, clip.n_frames, clip.info.fps, clip.info.width,
                                      clip.info.height, camera=camera, players=pl, frames=frames,
                                      keep_all=not ctx.cfg.rally_only)
    finally:
        frames.close()
    clip.write_events(result.events_with_timing())  # + confidence, sigma_frames (docs/formats.md §9)
    _write_rally(clip, result)
    counts: dict[str, int] = {}
    for e in result.events.event:
        counts[str(e)] = counts.get(str(e), 0) + 1
    if not len(result.events):
        raise StageError(f"{clip.ball_path}: no hit events found, so the flights cannot be cut — check ball.csv "
                         "(label or re-detect the ball) or pass another --events model")
    from inference.events.rally import rally_summary

    model = ("player-aware" if players is not None else "player-aware, no players") if det.wants_players \
        else "ball only"
    rally = f"; {rally_summary(result.rally, clip.info.fps, result.outside.event, not ctx.cfg.rally_only)}" \
        if result.rally is not None else ""
    unsure = result.unsure_all(clip.info.fps)
    return Outcome(clip.n_frames, f"{len(result.events)} events (" +
                   ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) + f"; {model})" +
                   (f" in {len(spans)} court-view scenes" if spans is not None else "") + rally +
                   (f"; check: {unsure}" if unsure else ""))


def _write_rally(clip, result) -> None:
    """rally.yaml beside events.csv: the point's start/end and the events outside it."""
    from inference.events.rally import write_rally_yaml

    if result.rally is not None:
        write_rally_yaml(clip.root / "rally.yaml", result.rally, clip.info.fps,
                         list(zip(result.outside.frame.tolist(), result.outside.event.tolist())))


def _players_for_events(ctx: Context):
    """The clip's players for the events stage (None when absent, empty or unreadable: ball only)."""
    from inference.clipio import FormatError

    if not ctx.clip.players_path.is_file():
        return None
    try:
        players = ctx.clip.read_players(missing_ok=True)
    except (FormatError, ValueError, OSError):
        return None
    return players if len(players) else None


def _events_weights(ctx: Context) -> Path:
    """The hit-event model file the stage will load (so a new shipped model invalidates the cache): ``--events``,
    else the shipped player-aware model (with or without players: :data:`~inference.events.detector.PLAYERS_OPTIONAL`)
    when one is shipped, else the ball-only one."""
    from inference.events.detector import choose_weights

    return choose_weights(ctx.cfg.events, ctx.clip.info.sport, _players_for_events(ctx))


def _events_inputs(ctx: Context) -> dict[str, Path | None]:
    from inference.events.detector import model_wants_players

    weights = _events_weights(ctx)
    players = ctx.clip.players_path if model_wants_players(weights) else None  # read only by player-aware models
    return {"ball": ctx.clip.ball_path, "camera": ctx.clip.root / "camera.yaml", "weights": weights,
            "players": players, "scenes": _scenes_path(ctx)}


# ------------------------------------------------------------------------------------------ players
def _players_run(ctx: Context) -> Outcome:
    from inference.players.backends import make_backend
    from inference.players.sampling import pose_stride
    from inference.players.tracking import TrackingConfig, in_play_area, players_from_poses

    clip = ctx.clip
    if not clip.camera_path.is_file():
        raise Skip("no calibration (players are placed on court through the camera)")
    name = ctx.cfg.pose
    if name == "none":
        raise Skip("--pose none")
    backend = make_backend("movenet" if name == "auto" else name, model=ctx.cfg.pose_model,
                           pose_model=ctx.cfg.pose_model)
    ok, reason = backend.available()
    if not ok:
        if name == "auto":
            raise Skip(f"no pose backend available ({reason})")
        raise StageError(f"pose backend {name!r}: {reason}")
    active = _court_frames(ctx)  # close-ups and replays: no pose search, no player rows
    stride = pose_stride(clip.info.fps, ctx.cfg.pose_every)
    camera = clip.read_camera()
    poses = backend.run(clip, progress=ctx.cfg.progress, active=active, stride=stride,
                        focus=in_play_area(camera, ctx.court))
    players = players_from_poses(poses, camera, ctx.court, clip.info.fps, TrackingConfig(), active=active)
    clip.write_players(players)
    note = f"{len(players.ids())} players"
    if stride > 1:
        note += f" (posed every {stride} frames)"
    if active is not None and not active.all():
        note += f" ({int((~active).sum())} frames outside court views not searched, {_scenes_path(ctx).name})"
    return Outcome(len(poses) if active is None else int(active.sum()), note)


def _players_outputs(ctx: Context) -> list[Path]:
    """players.csv, except with ``--pose none``: the stage writes nothing, and a players.csv the user brought
    (another tool's) is read by the events and reconstruct stages."""
    return [] if ctx.cfg.pose == "none" else [ctx.clip.players_path]


# -------------------------------------------------------------------------------------- reconstruct
def _reconstruct_run(ctx: Context) -> Outcome:
    from inference.reconstruct.api import reconstruct
    from inference.reconstruct.observations import Observations

    clip = ctx.clip
    if not clip.camera_path.is_file():
        raise Skip("no calibration")
    obs = Observations.from_clip(clip, court=ctx.court)
    stabilised = _camera_track_path(ctx).is_file()
    if stabilised:  # a drifting camera: the 2D ball moved back onto the calibrated camera's picture
        from inference.courtfit.drift import CameraTrack

        obs = obs.with_track(CameraTrack.read(_camera_track_path(ctx), clip.n_frames).stabilise(obs.uv))
    if not len(obs.event_frames):
        raise StageError(f"{clip.events_path}: needs at least one event (a bounce or a hit) to anchor the flight")
    spans = _court_spans(ctx)
    if spans is None:
        fit = reconstruct(obs, ctx.cfg.method)
    else:  # a broadcast clip: each court-view scene fitted on its own, no flight across a cut
        from .per_scene import reconstruct_per_scene

        fit = reconstruct_per_scene(obs, spans, ctx.cfg.method)
    fit.save(clip)
    ok = sum(s.ok for s in fit.segments)
    if ok == 0:
        reasons = "; ".join(sorted({s.reason for s in fit.segments if not s.ok})) or \
            f"no event in any court-view scene of {_scenes_path(ctx).name}"
        raise StageError(f"{clip.root}: no flight could be reconstructed ({reasons}) — check ball.csv and events.csv")
    # flights that cannot be fitted (too few detections between two events) are normal in a real rally: they
    # are listed in segments.json with their reason, and the run still counts as complete
    pl = fit.extra.get("plausibility", {})
    verdict = "" if not pl else (", plausible" if pl["plausible"] else
                                 f", NOT plausible ({'; '.join(pl.get('not_plausible_because', []))})")
    shift = f"; 2D stabilised by {_camera_track_path(ctx).name}" if stabilised else ""
    if spans is not None:
        shift += f"; {len(spans)} court-view scenes fitted apart ({_scenes_path(ctx).name})"
    return Outcome(fit.n_frames, f"{ok}/{len(fit.segments)} flights reconstructed{verdict}{shift}")


def _camera_track_path(ctx: Context) -> Path:
    return ctx.clip.root / "camera_track.csv"


def _file(name: str) -> Callable[[Context], Path]:
    return lambda ctx: ctx.clip.root / name


def _code(*packages: str) -> tuple[str, ...]:
    """Modules whose source keys a stage: its own ``inference`` packages, the clip format and this file."""
    return ("inference.clipio", "inference.pipeline.stages", "inference.pipeline.per_scene",
            *(f"inference.{p}" for p in packages))


def build_stages() -> list[Stage]:
    """The stages of ``rally3d infer`` in order."""
    video = lambda ctx: ctx.clip.video_path  # noqa: E731
    camera = _file("camera.yaml")
    return [
        Stage("camera", _camera_inputs,
              lambda ctx: {"court": str(ctx.clip.court_path()), "auto": ctx.cfg.auto_court}, _camera_outputs,
              _camera_run, code=_code("camera", "courtfit", "court")),
        Stage("scenes", lambda ctx: {"video": video(ctx), "camera": camera(ctx), "clip_yaml": ctx.clip.clip_yaml_path},
              lambda ctx: {"scenes": 1}, lambda ctx: [_scenes_output(ctx)], _scenes_run, code=_code("video")),
        Stage("detect", lambda ctx: {"video": video(ctx), "weights": _weights_path(ctx), "scenes": _scenes_path(ctx),
                                     "clip_yaml": ctx.clip.clip_yaml_path, "mask": ctx.clip.root / "mask_auto.yaml"},
              lambda ctx: {"model": ctx.cfg.detector, "step": ctx.cfg.step},
              lambda ctx: [ctx.detected_path], _detect_run, code=_code("detection", "models", "video")),
        Stage("smooth", lambda ctx: {"detected": ctx.detected_path, "scenes": _scenes_path(ctx)},
              lambda ctx: {},  # its version is its code's (Stage.code)
              lambda ctx: [ctx.clip.ball_path], _smooth_run, requires=("detect",), code=_code("detection.smooth")),
        Stage("players", lambda ctx: {"video": video(ctx), "camera": camera(ctx), "model": ctx.cfg.pose_model,
                                      "scenes": _scenes_path(ctx)},
              lambda ctx: {"pose": ctx.cfg.pose, "every": ctx.cfg.pose_every}, _players_outputs, _players_run,
              code=_code("players", "models", "camera", "court")),
        Stage("events", _events_inputs, lambda ctx: {"sport": ctx.clip.info.sport, "rally_only": ctx.cfg.rally_only},
              lambda ctx: [ctx.clip.events_path, ctx.clip.root / "rally.yaml"], _events_run,
              requires=("smooth",), code=_code("events", "players", "physics", "court")),
        Stage("reconstruct", lambda ctx: {"ball": ctx.clip.ball_path, "events": ctx.clip.events_path,
                                          "camera": camera(ctx), "players": ctx.clip.players_path,
                                          "camera_track": _camera_track_path(ctx), "scenes": _scenes_path(ctx)},
              lambda ctx: {"method": ctx.cfg.method},
              lambda ctx: [ctx.clip.ball_3d_path, ctx.clip.segments_path], _reconstruct_run,
              requires=("events",),
              code=_code("reconstruct", "detection.smooth", "physics", "events", "camera", "court")),
    ]
