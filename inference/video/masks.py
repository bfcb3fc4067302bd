"""Image regions to ignore (a broadcast's scoreboard, logos, a clock): clip.yaml's ``mask`` key.

``mask`` is a list of rectangles ``[x0, y0, x1, y1]`` in normalised image coordinates (docs/formats.md §4),
or ``auto``: the rectangles are found from the pixels that stay constant while the rest of the picture
changes (:func:`find_static_overlays`) and written to ``mask_auto.yaml`` (rectangles, editable) and
``mask_auto.jpg`` (a frame with them drawn) for the user to check; an existing ``mask_auto.yaml`` is used
as it stands, so a corrected file wins. The ball detector, the scene split and the automatic court fit see
those pixels filled with one flat colour, so a scoreboard's digits give no ball candidates and its edges no
court lines.

Example:
    >>> rects = clip_mask(clip)                  # [] when clip.yaml has no mask
    >>> frame = apply_mask(frame, rects)         # (H, W, 3) uint8, a copy when anything was masked
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from inference.clipio import Clip, FormatError

log = logging.getLogger(__name__)
FIX = "write mask as a list of [x0, y0, x1, y1] rectangles in normalised image coordinates, e.g. " \
      "mask: [[0.02, 0.03, 0.30, 0.12]], or mask: auto"
AUTO = "auto"
AUTO_FILE = "mask_auto.yaml"
AUTO_PREVIEW = "mask_auto.jpg"
#: the automatic mask: frames sampled, working width (px), static threshold relative to the clip's typical
#: temporal spread, the smallest spread (grey levels) below which a clip is too still to tell, box limits
AUTO_SAMPLES = 24
AUTO_WIDTH = 640
STATIC_OF_TYPICAL = 0.25
MIN_TYPICAL_SPREAD = 1.0
EDGE_MIN = 80.0  # Sobel magnitude of an edge (a step of ~20 grey levels)
BOX_AREA = (0.0005, 0.08)  # of the image
BOX_FILL_MIN = 0.4
BOX_EDGE_PIXELS = 30
COURT_SHARE_MAX = 0.03  # of the projected court-line samples inside a box


@dataclass(frozen=True)
class MaskRect:
    """A rectangle to ignore, normalised coordinates, ``0 ≤ x0 < x1 ≤ 1`` and ``0 ≤ y0 < y1 ≤ 1``."""

    x0: float
    y0: float
    x1: float
    y1: float

    def __post_init__(self) -> None:
        if not (0 <= self.x0 < self.x1 <= 1 and 0 <= self.y0 < self.y1 <= 1):
            raise ValueError(f"[{self.x0}, {self.y0}, {self.x1}, {self.y1}] is not a rectangle inside [0, 1]²")

    def pixels(self, width: int, height: int) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1) whole pixels covering the rectangle."""
        return (int(np.floor(self.x0 * width)), int(np.floor(self.y0 * height)),
                int(np.ceil(self.x1 * width)), int(np.ceil(self.y1 * height)))


def parse_mask(value, where) -> list[MaskRect]:
    """clip.yaml's ``mask`` value (not ``auto``) → rectangles; :class:`FormatError` naming ``where`` and the
    entry."""
    if value is None:
        return []
    if not isinstance(value, list):
        raise FormatError(where, "mask must be a list of rectangles", fix=FIX)
    rects = []
    for k, r in enumerate(value):
        try:
            if isinstance(r, bool) or not isinstance(r, list) or len(r) != 4:
                raise ValueError("expected 4 numbers")
            rects.append(MaskRect(*(float(v) for v in r)))
        except (TypeError, ValueError) as e:
            raise FormatError(where, f"mask entry {k + 1} ({r!r}): {e}", fix=FIX) from None
    return rects


def clip_mask(clip: Clip) -> list[MaskRect]:
    """The rectangles of ``clip``'s clip.yaml ``mask`` key ([] when there is none); ``auto``: those of
    ``mask_auto.yaml``, found and written first when it does not exist (or describes another video)."""
    value = clip.info.extra.get("mask")
    if value == AUTO:
        return auto_clip_mask(clip).rects
    return parse_mask(value, clip.clip_yaml_path)


# ---------------------------------------------------------------------------------------- automatic
@dataclass
class AutoMask:
    """Rectangles over static overlays and what the search saw.

    Attributes:
        rects: the boxes (normalised). spread: the clip's typical temporal spread (grey levels; median
            per-pixel standard deviation over the sampled frames). notes: why nothing was found, if so.
    """

    rects: list[MaskRect]
    spread: float = 0.0
    notes: list[str] = field(default_factory=list)


def find_static_overlays(frames: list[np.ndarray], court_px: np.ndarray | None = None) -> AutoMask:
    """Boxes over what stays constant while the picture changes (a burnt-in scoreboard, a channel logo).

    Args:
        frames: ≥ 8 RGB (H, W, 3) frames spread over the clip.
        court_px: (P, 2) full-resolution pixels on the calibrated court lines; a box holding more than
            :data:`COURT_SHARE_MAX` of them is the court itself and is never masked.

    Only edges count (flat areas say nothing: compression flattens them too). An edge pixel of the median
    frame is static when its standard deviation over the frames is below :data:`STATIC_OF_TYPICAL` × the
    median one of all edge pixels: camera noise, drift and players move the court's edges, not a keyed-in
    graphic's. Static edge pixels are grouped (a closing about 2.5 % of the width joins a scoreboard's
    letters, then connected components); a group becomes a box when it is compact (fills ≥
    :data:`BOX_FILL_MIN` of its bounding box) and between :data:`BOX_AREA` of the image: long thin court
    lines are neither. A clip whose edges do not change at all (a noiseless synthetic clip) cannot be told
    apart from its overlays: nothing is masked, and a note says so.
    """
    import cv2

    h, w = frames[0].shape[:2]
    scale = min(1.0, AUTO_WIDTH / w)
    size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
    stack = np.stack([cv2.resize(f, size, interpolation=cv2.INTER_AREA).astype(np.float32) for f in frames])
    spread_px = stack.std(axis=0).max(axis=2)
    grey = np.median(stack, axis=0).mean(axis=2).astype(np.float32)
    edges = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1)) > EDGE_MIN
    spread = float(np.median(spread_px[edges])) if edges.any() else 0.0
    if spread < MIN_TYPICAL_SPREAD:
        return AutoMask([], spread, [f"the picture hardly changes (median spread {spread:.2f} grey levels on its "
                                     "edges): overlays cannot be told from the court; no automatic mask"])
    static = (edges & (spread_px < STATIC_OF_TYPICAL * spread)).astype(np.uint8)
    k = max(3, int(round(0.025 * size[0])) | 1)
    grouped = cv2.morphologyEx(static, cv2.MORPH_CLOSE, np.ones((k, k), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(grouped, connectivity=8)
    court = None if court_px is None or not len(court_px) else court_px * scale
    rects, notes = [], []
    for i in range(1, n):
        x, y, bw, bh, area = (int(v) for v in stats[i])
        share = bw * bh / (size[0] * size[1])
        if not BOX_AREA[0] <= share <= BOX_AREA[1] or area < BOX_FILL_MIN * bw * bh:
            continue
        if static[labels == i].sum() < BOX_EDGE_PIXELS:
            continue
        m = 0.01 * size[0]  # a margin: the box's antialiased border
        x0, y0, x1, y1 = max(0, x - m), max(0, y - m), min(size[0], x + bw + m), min(size[1], y + bh + m)
        if court is not None:
            inside = (court[:, 0] >= x0) & (court[:, 0] < x1) & (court[:, 1] >= y0) & (court[:, 1] < y1)
            if inside.mean() > COURT_SHARE_MAX:
                notes.append(f"a static region at x {x0 / size[0]:.2f}–{x1 / size[0]:.2f}, y {y0 / size[1]:.2f}–"
                             f"{y1 / size[1]:.2f} covers the court's lines: not masked")
                continue
        rects.append(MaskRect(x0 / size[0], y0 / size[1], x1 / size[0], y1 / size[1]))
    return AutoMask(rects, spread, notes)


def auto_clip_mask(clip: Clip, samples: int = AUTO_SAMPLES) -> AutoMask:
    """``mask: auto`` of ``clip``: ``mask_auto.yaml`` when it exists for this video, else found from
    ``samples`` frames (the calibrated court excluded when camera.yaml exists) and written with its preview."""
    path = clip.root / AUTO_FILE
    n, size = clip.n_frames, [clip.info.width, clip.info.height]
    if path.is_file():
        from inference.clipio.structured import load_yaml

        data = load_yaml(path)
        if isinstance(data, dict) and data.get("n_frames") == n and data.get("size") == size:
            return AutoMask(parse_mask(data.get("mask") or [], path), float(data.get("spread", 0.0)))
        log.info("%s describes another video: found again", path)
    idx = np.unique(np.linspace(0, n - 1, min(samples, n)).round().astype(int))
    with clip.frames(cache_size=0) as src:
        frames = [src.read(int(i)) for i in idx]
    court_px = None
    if clip.camera_path.is_file():
        from inference.court import load_court
        from inference.courtfit.model import court_line_samples

        court_px = court_line_samples(clip.read_camera(), load_court(clip.court_path()))
    found = find_static_overlays(frames, court_px)
    _write_auto(clip, found, frames[len(frames) // 2])
    return found


def _write_auto(clip: Clip, found: AutoMask, frame: np.ndarray) -> None:
    import cv2
    import yaml

    from inference.clipio.atomic import atomic_write_bytes, atomic_write_text

    body = {"mask": [[round(v, 4) for v in (r.x0, r.y0, r.x1, r.y1)] for r in found.rects],
            "n_frames": clip.n_frames, "size": [clip.info.width, clip.info.height], "spread": round(found.spread, 3)}
    head = ("# rally3d's automatic mask (clip.yaml: mask: auto): boxes over pixels that stay constant while the\n"
            "# picture changes. Check mask_auto.jpg; edit the boxes here ([x0, y0, x1, y1], normalised) and this\n"
            "# file is used as it stands. Delete it to search again.\n")
    head += "".join(f"# note: {n}\n" for n in found.notes)
    atomic_write_text(clip.root / AUTO_FILE, head + yaml.safe_dump(body, sort_keys=False, default_flow_style=None))
    img = np.ascontiguousarray(frame[..., ::-1])
    h, w = img.shape[:2]
    for r in found.rects:
        x0, y0, x1, y1 = r.pixels(w, h)
        cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), (0, 0, 255), max(2, w // 400))
    ok, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])
    if ok:
        atomic_write_bytes(clip.root / AUTO_PREVIEW, jpg.tobytes())


def apply_mask(frame: np.ndarray, rects: list[MaskRect]) -> np.ndarray:
    """``frame`` (H, W, 3) with every rectangle filled with the median colour of the frame's border around
    it (flat: no edges, no ball-like blobs); the input is not changed."""
    if not rects:
        return frame
    out = frame.copy()
    h, w = frame.shape[:2]
    for r in rects:
        x0, y0, x1, y1 = r.pixels(w, h)
        ring = np.concatenate([frame[max(y0 - 2, 0):y0, x0:x1].reshape(-1, 3),
                               frame[y1:y1 + 2, x0:x1].reshape(-1, 3),
                               frame[y0:y1, max(x0 - 2, 0):x0].reshape(-1, 3),
                               frame[y0:y1, x1:x1 + 2].reshape(-1, 3)])
        out[y0:y1, x0:x1] = np.median(ring, axis=0) if len(ring) else 0
    return out
