"""A whole match through ``rally3d infer``: one pass to find the rallies, then one clip folder per rally.

A match video (1–3 h) is never held whole. :func:`scan_video` decodes it once and keeps, per frame, only the
mean difference of its 48×27 thumbnail to the previous frame's, and one mean thumbnail per half second
(a 30-minute 25 fps match: 45,000 floats and 3,600 thumbnails, ~56 MB). From them :func:`plan_rallies`

1. cuts the video into scenes where the editor cut (:func:`inference.video.scenes.cuts_from_diffs`, the same
   rule as a clip's ``scenes.json``);
2. keeps the court views: the scenes that look like the main view (the longest scene), within
   :data:`inference.video.scenes.SIMILAR_MAX` grey levels of it; replays, close-ups and crowd shots are left out;
3. drops court views shorter than ``min_rally_s`` (a glimpse between two replays is no rally), cuts a court view
   in the middle of every pause (the players walking back between points: the picture's motion low for
   ``pause_s``; a piece that is nearly all pause is dropped) and splits a piece still longer than ``max_rally_s``
   (a club camera never cuts) at its quietest second, into stretches of ``min_rally_s .. max_rally_s``.

Each stretch becomes a clip folder ``rally_NNN/`` under the output folder (its frames re-encoded, as
``--start/--end`` writes them) and runs through the whole pipeline; the rally segmentation of the events stage
(``rally.yaml``) then says where the point starts and ends inside it. ``index.csv`` lists every rally — its
frames and seconds in the match, its status, events, the point's serve — and ``match.json`` holds the scan and
the status for resuming: a second run skips the scan and the rallies already done and re-runs an interrupted
or failed one (its finished stages are reused). A failing rally is recorded and the next one runs.

Progress goes to the terminal and to ``match.log`` in the output folder: the scan's frames/s, each rally done,
the frames/s of the pipeline, and the time left (docs/pipeline.md, "A whole match").

Example:
    >>> plan = plan_rallies(scan_video(Path("final.mp4")), MatchParams())
    >>> code = run_match(Path("final.mp4"), Path("runs/match/final"), "padel", cfg)
"""
from __future__ import annotations

import csv
import io
import json
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

MATCH_VERSION = 1
MATCH_FILE = "match.json"
INDEX_FILE = "index.csv"
LOG_FILE = "match.log"
#: a video longer than this (seconds) is a match: ``rally3d infer`` splits it into rallies unless ``--whole``
MATCH_ABOVE_S = 600.0
INDEX_COLUMNS = ("rally", "clip", "first_frame", "stop_frame", "start_s", "end_s", "status", "events", "serve",
                 "point_start_s", "point_end_s", "seconds", "note")


@dataclass(frozen=True)
class MatchParams:
    """How a match is split into rallies.

    Attributes:
        min_rally_s: a court view shorter than this is not a rally (a glimpse between replays).
        max_rally_s: a longer court view (a club camera that never cuts) is split at its quietest moments.
        quiet_s: seconds over which the picture's motion is averaged to find the quietest moment.
        pause_s, pause_ratio: a court view is also cut in every pause at least ``pause_s`` long whose motion
            stays below ``pause_ratio`` × the view's median (the players walking back between points); a piece
            of a view cut so whose median motion is that low is a pause, not a rally: dropped.
        block_s: the scan keeps one mean thumbnail per this many seconds (what tells court views).
    """

    min_rally_s: float = 4.0
    max_rally_s: float = 90.0
    quiet_s: float = 1.0
    pause_s: float = 3.0
    pause_ratio: float = 0.3
    block_s: float = 0.5

    def __post_init__(self) -> None:
        if not 0 < self.min_rally_s < self.max_rally_s:
            raise ValueError(f"min_rally_s must be > 0 and below max_rally_s, got {self.min_rally_s}, "
                             f"{self.max_rally_s}")
        if self.max_rally_s < 2 * self.min_rally_s:
            raise ValueError(f"max_rally_s ({self.max_rally_s}) must be at least twice min_rally_s "
                             f"({self.min_rally_s}): a long view is split into pieces of at least min_rally_s")
        if self.quiet_s <= 0 or self.block_s <= 0:
            raise ValueError(f"quiet_s and block_s must be > 0, got {self.quiet_s}, {self.block_s}")


@dataclass
class Scan:
    """What one pass over a match keeps.

    Attributes:
        diffs: ``(n_frames - 1,) float32``: frame ``i + 1``'s thumbnail vs frame ``i``'s (grey levels).
        blocks: ``(n_blocks, 27, 48, 3) float32`` mean thumbnails of consecutive ``block`` frames.
        block: frames per block; fps, n_frames: of the video as the clips read it.
    """

    diffs: np.ndarray
    blocks: np.ndarray
    block: int
    fps: float
    n_frames: int

    def scenes(self) -> list[tuple[int, int, bool, float]]:
        """``[(start, stop, court_view, difference to the main view), ...]`` covering every frame."""
        from inference.video.scenes import SIMILAR_MAX, cuts_from_diffs

        bounds = [0, *cuts_from_diffs(self.diffs, self.fps), self.n_frames]
        spans = list(zip(bounds[:-1], bounds[1:]))
        if len(spans) == 1:
            return [(0, self.n_frames, True, 0.0)]
        means = [self._mean(a, b) for a, b in spans]
        main = means[int(np.argmax([b - a for a, b in spans]))]
        out = []
        for (a, b), m in zip(spans, means):
            diff = float(np.abs(m - main).mean())
            out.append((a, b, diff <= SIMILAR_MAX, round(diff, 3)))
        return out

    def _mean(self, a: int, b: int) -> np.ndarray:
        """Mean thumbnail of frames ``a .. b-1`` from the blocks that lie inside (the middle one if none does)."""
        first, last = -(-a // self.block), b // self.block  # blocks wholly inside
        if last <= first:
            return self.blocks[min((a + b) // 2 // self.block, len(self.blocks) - 1)]
        return self.blocks[first:last].mean(axis=0)

    def motion(self, quiet: int) -> np.ndarray:
        """``(n_frames,)``: the picture's motion around each frame, averaged over ``quiet`` frames."""
        d = np.concatenate([[0.0], self.diffs.astype(np.float64)])
        k = max(1, int(quiet))
        return np.convolve(d, np.ones(k) / k, mode="same")


@dataclass
class Rally:
    """One stretch of the match that becomes a clip folder, and how its run went.

    Attributes:
        rally: 1-based number; first_frame, stop_frame: frames ``first .. stop-1`` of the match.
        status: ``pending``, ``done``, ``incomplete`` (a stage failed; partial results kept), ``failed``
            (nothing usable: the reason in ``note``) or ``interrupted``.
        events, serve, point_start_s, point_end_s: from the clip's events.csv and rally.yaml (match seconds).
    """

    rally: int
    first_frame: int
    stop_frame: int
    status: str = "pending"
    events: int | None = None
    serve: str = ""
    point_start_s: float | None = None
    point_end_s: float | None = None
    seconds: float | None = None
    note: str = ""

    @property
    def clip(self) -> str:
        return f"rally_{self.rally:03d}"

    @property
    def n_frames(self) -> int:
        return self.stop_frame - self.first_frame


def is_video_file(path: Path) -> bool:
    """A video file (by its suffix), not a clip folder."""
    from .prepare import VIDEO_SUFFIXES, is_clip_folder

    return not is_clip_folder(path) and Path(path).suffix.lower() in VIDEO_SUFFIXES


def is_long_video(path: Path, above_s: float = MATCH_ABOVE_S) -> bool:
    """A video file longer than ``above_s`` seconds: a match (``rally3d infer`` splits it into rallies)."""
    from .prepare import probe_video

    if not is_video_file(path):
        return False
    _, _, fps, n = probe_video(Path(path))
    return n / fps > above_s


def scan_video(video: Path, params: MatchParams | None = None, progress: Callable[[int, int], None] | None = None
               ) -> Scan:
    """Decode ``video`` once (as a clip reads it: repeated pictures of a converted broadcast left out) and keep
    the per-frame differences and block thumbnails of :class:`Scan`. ``progress(done, total)`` is called now
    and then."""
    from inference.clipio.frames import FrameSource
    from inference.video.scenes import thumbnail

    from .prepare import _content

    params = params or MatchParams()
    _, _, fps, n, _, repeats = _content(video)
    block = max(1, int(round(params.block_s * fps)))
    diffs = np.zeros(max(n - 1, 0), np.float32)
    blocks: list[np.ndarray] = []
    acc, count, prev, i = None, 0, None, 0
    with FrameSource.open(video, cache_size=0, repeats=repeats) as src:
        for i, frame in enumerate(src.iter(0, n)):
            t = thumbnail(frame)
            if prev is not None:
                diffs[i - 1] = float(np.abs(t - prev).mean())
            prev = t
            acc = t.copy() if acc is None else acc + t
            count += 1
            if count == block:
                blocks.append(acc / count)
                acc, count = None, 0
            if progress is not None and (i + 1) % 250 == 0:
                progress(i + 1, n)
    if acc is not None:
        blocks.append(acc / count)
    seen = i + 1 if prev is not None else 0
    if progress is not None:
        progress(seen, n)
    return Scan(diffs[:max(seen - 1, 0)], np.stack(blocks) if blocks else np.zeros((1, 27, 48, 3), np.float32),
                block, float(fps), seen)


def quiet_runs(motion: np.ndarray, a: int, b: int, below: float, min_len: int) -> list[tuple[int, int]]:
    """``[(first, stop), ...]``: stretches of frames ``a .. b-1`` at least ``min_len`` long whose ``motion`` is
    below ``below``."""
    low = np.concatenate([[False], motion[a:b] < below, [False]])
    edges = np.flatnonzero(np.diff(low.astype(np.int8)))
    return [(a + s, a + e) for s, e in zip(edges[::2], edges[1::2]) if e - s >= min_len]


def split_view(a: int, b: int, motion: np.ndarray, fps: float, params: MatchParams) -> list[tuple[int, int]]:
    """Frames ``a .. b-1`` of one court view as rallies: cut in the middle of every pause (``pause_s`` or more
    with the picture's motion below ``pause_ratio`` × the view's median: the players walking back between
    points), no piece shorter than ``min_rally_s``; a piece still longer than ``max_rally_s`` is cut at its
    quietest moment (:func:`split_long`)."""
    lo = int(round(params.min_rally_s * fps))
    cuts = [a]
    below = params.pause_ratio * float(np.median(motion[a:b])) if b > a else 0.0
    for s, e in quiet_runs(motion, a, b, below, int(round(params.pause_s * fps))):
        c = int((s + e) // 2)
        if c - cuts[-1] >= lo and b - c >= lo:
            cuts.append(c)
    bounds = [*cuts, b]
    pieces = [p for x, y in zip(bounds[:-1], bounds[1:]) for p in split_long(x, y, motion, fps, params)]
    if len(bounds) == 2:
        return pieces
    # a pause split in two (the light changes, the players cross the picture) leaves a piece between its halves
    # that is pause all the same: as still as a pause for most of its frames (its median)
    return [(x, y) for x, y in pieces if np.median(motion[x:y]) >= below]


def split_long(a: int, b: int, motion: np.ndarray, fps: float, params: MatchParams) -> list[tuple[int, int]]:
    """Frames ``a .. b-1`` in pieces of ``min_rally_s .. max_rally_s``: while a piece is too long it is cut in
    the middle of its quietest stretch (least ``motion``; of equally quiet ones the nearest the middle) that
    leaves both sides at least ``min_rally_s``."""
    lo, hi = int(round(params.min_rally_s * fps)), int(round(params.max_rally_s * fps))
    if b - a <= hi:
        return [(a, b)]
    first, last = a + lo, b - lo
    m = motion[first:last + 1]
    calm = quiet_runs(m, 0, len(m), float(m.min()) + 1e-6 + 0.05 * float(np.ptp(m)), 1)
    middle = (len(m) - 1) / 2
    cut = first + int(min(((s + e - 1) // 2 for s, e in calm), key=lambda x: abs(x - middle)))
    return [*split_long(a, cut, motion, fps, params), *split_long(cut, b, motion, fps, params)]


def plan_rallies(scan: Scan, params: MatchParams | None = None) -> list[Rally]:
    """The rallies of a scanned match (module docstring), numbered from 1 in order."""
    params = params or MatchParams()
    motion = scan.motion(int(round(params.quiet_s * scan.fps)))
    spans: list[tuple[int, int]] = []
    for a, b, court_view, _ in scan.scenes():
        if court_view and (b - a) >= params.min_rally_s * scan.fps:
            spans.extend(split_view(a, b, motion, scan.fps, params))
    return [Rally(k + 1, int(a), int(b)) for k, (a, b) in enumerate(spans)]


# ------------------------------------------------------------------------------------------ the index
@dataclass
class MatchIndex:
    """``match.json``: the video, the split, every rally's status (what a resumed run reads)."""

    video: str
    fingerprint: str
    params: dict
    fps: float
    n_frames: int
    scenes: list = field(default_factory=list)
    rallies: list[Rally] = field(default_factory=list)
    stages: str = "all"
    version: int = MATCH_VERSION

    def write(self, out: Path) -> None:
        """Write ``match.json`` and ``index.csv`` into ``out`` (each replaced atomically)."""
        from inference.clipio.atomic import atomic_write_text

        d = asdict(self)
        atomic_write_text(out / MATCH_FILE, json.dumps(d, indent=1) + "\n")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(INDEX_COLUMNS)
        for r in self.rallies:
            w.writerow([r.rally, r.clip, r.first_frame, r.stop_frame, f"{r.first_frame / self.fps:.2f}",
                        f"{r.stop_frame / self.fps:.2f}", r.status, "" if r.events is None else r.events, r.serve,
                        _num(r.point_start_s), _num(r.point_end_s), _num(r.seconds, 1), r.note])
        atomic_write_text(out / INDEX_FILE, buf.getvalue())

    @classmethod
    def read(cls, path: Path) -> MatchIndex:
        """Read ``match.json``; a :class:`~inference.clipio.FormatError` naming the file when malformed."""
        from inference.clipio import FormatError
        from inference.clipio.structured import load_json

        d = load_json(path)
        try:
            rallies = [Rally(**r) for r in d.pop("rallies")]
            return cls(**d, rallies=rallies)
        except (KeyError, TypeError, ValueError) as e:
            raise FormatError(path, f"not a match index ({e!r})",
                              fix=f"delete {path.name} and re-run rally3d infer: the match is scanned again and "
                              "the rallies already written are reused") from None

    def summary(self) -> str:
        n = {s: sum(r.status == s for r in self.rallies) for s in ("done", "incomplete", "failed", "pending",
                                                                     "interrupted")}
        play = sum(r.n_frames for r in self.rallies) / self.fps
        return (f"{len(self.rallies)} rallies ({play / 60:.1f} min of {self.n_frames / self.fps / 60:.1f} min of video): "
                + ", ".join(f"{v} {k}" for k, v in n.items() if v))


def parse_rallies(text: str | None) -> set[int] | None:
    """``--rallies 1-3,7`` → ``{1, 2, 3, 7}`` (None: every rally); a clear error for anything else."""
    if text is None:
        return None
    out: set[int] = set()
    try:
        for part in filter(None, (p.strip() for p in str(text).split(","))):
            a, _, b = part.partition("-")
            lo, hi = int(a), int(b or a)
            if lo < 1 or hi < lo:
                raise ValueError
            out.update(range(lo, hi + 1))
    except ValueError:
        raise ValueError(f"--rallies {text!r}: give rally numbers from 1, like 3 or 1-3,7") from None
    if not out:
        raise ValueError(f"--rallies {text!r}: give rally numbers from 1, like 3 or 1-3,7")
    return out


def _num(v: float | None, nd: int = 2) -> str:
    return "" if v is None else f"{v:.{nd}f}"


# ------------------------------------------------------------------------------------------- progress
class MatchLog:
    """Progress lines to the terminal (stderr) and, with a time stamp, to ``match.log``."""

    def __init__(self, path: Path, quiet: bool = False):
        self.path, self.quiet = path, quiet
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()

    def __call__(self, msg: str) -> None:
        if not self.quiet:
            print(msg, file=sys.stderr, flush=True)
        self.file_only(msg)

    def file_only(self, msg: str) -> None:
        self._file.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {msg}\n")
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def duration(seconds: float) -> str:
    """``1h02m``, ``4m05s``, ``12s``."""
    s = int(round(max(0.0, seconds)))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Throughput:
    """Frames done against frames to do; the rate and the time left (from the work done in this run)."""

    def __init__(self, total: int):
        self.total, self.done, self.t0 = int(total), 0, time.perf_counter()

    def add(self, frames: int) -> None:
        self.done += int(frames)

    def line(self) -> str:
        dt = time.perf_counter() - self.t0
        rate = self.done / dt if dt > 0 and self.done else float("nan")
        left = (self.total - self.done) / rate if rate == rate and rate > 0 else float("nan")
        eta = duration(left) if left == left else "?"
        return f"{rate:.1f} frames/s, ETA {eta}" if rate == rate else "ETA ?"


# ---------------------------------------------------------------------------------------------- the run
def stages_key(only: set[str] | None) -> str:
    """How ``match.json`` records the stages a run ran (``--only``): ``all`` or ``camera,scenes``."""
    return "all" if only is None else ",".join(sorted(only))


def load_or_plan(video: Path, out: Path, params: MatchParams, log: MatchLog, only: set[str] | None = None
                 ) -> MatchIndex:
    """The index of a previous run on the same video with the same split, or a fresh scan and plan. A run
    with other stages (``--only``) than the previous one runs every rally again (its finished stages reused)."""
    from .state import fingerprint

    fp = fingerprint(video) or ""
    path = out / MATCH_FILE
    if path.is_file():
        old = MatchIndex.read(path)
        if old.fingerprint == fp and old.params == asdict(params):
            if old.stages != stages_key(only):
                log(f"rally3d infer: {path} was run with stages {old.stages}, now {stages_key(only)}: every rally "
                    "runs again (stages already done are reused)")
                for r in old.rallies:
                    r.status = "pending" if r.status == "done" else r.status
                old.stages = stages_key(only)
                return old
            done = sum(r.status == "done" for r in old.rallies)
            log(f"rally3d infer: resuming {path}: {done} of {len(old.rallies)} rallies done")
            return old
        log(f"rally3d infer: {path} is of another video or another split: the match is scanned again "
            "(rally folders of the same frames are reused)")
    t0 = time.perf_counter()
    last = [0.0]

    def tick(done: int, total: int) -> None:
        now = time.perf_counter()
        if now - last[0] >= 10.0 or done >= total:
            last[0] = now
            rate = done / max(now - t0, 1e-9)
            left = duration((total - done) / rate) if rate > 0 else "?"
            log(f"[scan] {done}/{total} frames ({100 * done / max(total, 1):.0f} %), {rate:.0f} frames/s, ETA {left}")

    scan = scan_video(video, params, tick)
    rallies = plan_rallies(scan, params)
    index = MatchIndex(str(video), fp, asdict(params), scan.fps, scan.n_frames,
                       [list(s) for s in scan.scenes()], rallies, stages_key(only))
    index.write(out)
    log(f"[scan] {len(index.scenes)} scenes, {sum(s[2] for s in index.scenes)} court views → {index.summary()} "
        f"(took {duration(time.perf_counter() - t0)}); the split: {out / INDEX_FILE}")
    return index


def _rally_facts(clip, rally: Rally, fps: float) -> None:
    """Fill the rally's events, serve and point bounds (match seconds) from its clip folder (unreadable files:
    left empty; the clip's own run said why)."""
    from inference.clipio.structured import load_yaml
    from inference.events.rally import read_rally_yaml

    if (clip.root / "events.csv").is_file():
        try:
            rally.events = len(clip.read_events().frame)
        except (OSError, ValueError):
            rally.events = None
    path = clip.root / "rally.yaml"
    if path.is_file():
        try:
            start, end = read_rally_yaml(path)
            serve = (load_yaml(path) or {}).get("serve")
        except (OSError, ValueError):
            return
        rally.point_start_s = (rally.first_frame + start) / fps
        rally.point_end_s = (rally.first_frame + end) / fps
        rally.serve = str(serve or "")[:60]


def run_match(video: Path, out: Path, court: str, cfg, *, camera: Path | None = None,
              court_points: Path | None = None, params: MatchParams | None = None, only: set[str] | None = None,
              rallies: set[int] | None = None, quiet: bool = False, run_one: Callable | None = None) -> int:
    """Split ``video`` into rallies and run the pipeline on each (module docstring). Returns the exit code:
    0 when every rally is done, 1 when some are incomplete or failed (the others are kept), 130 on Ctrl-C.

    ``only``: the stages to run (``--only``); ``rallies``: run only these rally numbers now (``--rallies``; the
    others keep their status); ``run_one(clip, cfg, only=, log=)`` → a report with ``ok``,
    ``stages`` and ``table()``: the pipeline (default :func:`inference.pipeline.run.run_pipeline`)."""
    from inference.clipio import FormatError

    from .prepare import Cut, prepare
    from .run import run_pipeline

    import dataclasses

    params = params or MatchParams()
    run_one = run_one or run_pipeline
    cfg = dataclasses.replace(cfg, progress=False)  # one line per rally, not a bar per stage
    out = Path(out)
    log = MatchLog(out / LOG_FILE, quiet=quiet)
    try:
        log(f"rally3d infer: {video} is a match: split into rallies, one clip folder each in {out} "
            f"(log: {out / LOG_FILE})")
        try:
            index = load_or_plan(Path(video), out, params, log, only)
        except KeyboardInterrupt:
            log("rally3d infer: stopped during the scan (nothing written yet); re-run the same command to start again")
            return 130
        if not index.rallies:
            log(f"rally3d infer: no rally found in {video}: no court view of {params.min_rally_s:g} s or more "
                f"({len(index.scenes)} scenes, {sum(bool(s[2]) for s in index.scenes)} court views; see "
                f"{out / MATCH_FILE}). Lower --min-rally, or run it as one clip with --whole")
            return 1
        if rallies is not None:
            unknown = sorted(set(rallies) - {r.rally for r in index.rallies})
            if unknown:
                raise ValueError(f"--rallies {','.join(map(str, unknown))}: the match has rallies 1–"
                                 f"{len(index.rallies)} (see {out / INDEX_FILE})")
        todo = [r for r in index.rallies if r.status != "done" and (rallies is None or r.rally in rallies)]
        meter = Throughput(sum(r.n_frames for r in todo))
        fps = index.fps
        for r in todo:
            t0 = time.perf_counter()
            where = f"rally {r.rally}/{len(index.rallies)} ({r.first_frame / fps:.1f}–{r.stop_frame / fps:.1f} s)"
            try:
                prepared = prepare(Path(video), out / r.clip, court, camera, court_points,
                                   Cut(r.first_frame / fps, r.stop_frame / fps))
                report = run_one(prepared.clip, cfg, only=only, log=log.file_only)
                log.file_only(f"{where}:\n{report.table()}")
                r.status = "done" if report.ok else "incomplete"
                bad = [f"{s.name} {s.status}" for s in report.stages
                       if s.status in ("failed", "partial", "skipped", "blocked") and s.name != "players"]
                r.note = "; ".join(bad)
                _rally_facts(prepared.clip, r, fps)
            except KeyboardInterrupt:
                r.status, r.note = "interrupted", "stopped by the user: re-run the same command to resume"
                r.seconds = time.perf_counter() - t0
                index.write(out)
                log(f"{where} interrupted; {index.summary()}. Re-run the same command to resume.")
                return 130
            except (FormatError, OSError, ValueError, RuntimeError) as e:
                r.status, r.note = "failed", (str(e).splitlines() or [type(e).__name__])[0][:300]
            r.seconds = time.perf_counter() - t0
            meter.add(r.n_frames)
            index.write(out)
            log(f"{where} {r.status}" + (f" ({r.note})" if r.note else "") +
                f" in {duration(r.seconds)}; {meter.done}/{meter.total} frames, {meter.line()}")
        log(f"rally3d infer: {index.summary()}; index: {out / INDEX_FILE}")
        asked = [r for r in index.rallies if rallies is None or r.rally in rallies]
        return 0 if all(r.status == "done" for r in asked) else 1
    finally:
        log.close()
