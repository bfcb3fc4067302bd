"""Fuzz tests (hypothesis) of the CVAT and Label Studio importers: whatever the file holds, an import gives
labels or raises :class:`FormatError` — never another exception (and never a hang or a memory blow-up).

Each importer gets random bytes, and documents shaped like the real exports: CVAT XML with a task or a job
``<meta>`` (sizes, start frames, frame filters, ``original_size`` in either place) and tracks of shapes and
tags; Label Studio JSON tasks with annotations and predictions of ``videorectangle`` and ``timelinelabels``
regions. Half the documents are clean (real values; only frame numbers and positions vary, sometimes to
absurd ones such as frame 10^23), half chaotic (any value may be junk), so both the deep paths and the
error paths get examples. A last target runs the whole ``rally3d import`` path (import, then writing the
clip folder). The default profile is derandomized (the same examples on every run, so the suite cannot
flake); for a longer random search::

    RALLY3D_FUZZ=3000 .venv/bin/python -m pytest tests/inference/interchange/test_interchange_fuzz.py
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from inference.clipio import FormatError  # noqa: E402
from inference.interchange.common import LabelMap, write_into_clip  # noqa: E402
from inference.interchange.cvat import import_cvat  # noqa: E402
from inference.interchange.labelstudio import import_labelstudio  # noqa: E402

N = int(os.environ.get("RALLY3D_FUZZ", "0"))
settings.register_profile(
    "suite",
    max_examples=60,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)
settings.register_profile(
    "search", max_examples=max(N, 1), deadline=None, database=None, suppress_health_check=list(HealthCheck)
)
FUZZ = settings.get_profile("search" if N else "suite")

LABELS = ["ball", "pelota", "ground", "net", "player_far", "out_of_frame", "hard_to_see", "occluded",
          "player", "", "é"]
BALLISH = ["ball"] * 8 + LABELS
EVENTISH = ["ground", "net", "player_far", "player_near"] * 2 + LABELS
FRAMES = [0, 1, 2, 3, 4, 5, 9, 10, 29, 30, 31, 100, 999, 3_456_000, 2 * 10**9, 10**23, -1]
"""Frame numbers: real ones, the bounds, absurd ones (a legal frame near the bound would only be slow)."""
CELLS = ["", "0", "1", "2", "3", "-1", "0.5", "1e23", "1e400", "nan", "inf", "-0", " 7 ", "step=2", "step=0",
         "step=", "1,1", "1,1;2,2", "640.0,360.0", "x", "True", "&amp;", "é", "9" * 5000]
BAD_TEXT = ["\x00", "\ud800", "\x1f", "]]>", "<", "&"]
"""Text that breaks the file's encoding or syntax, put into a few shaped documents."""

printable = st.characters(blacklist_categories=("Cs", "Cc"))
text_cell = st.one_of(st.sampled_from(CELLS), st.integers(-5, 2000).map(str), st.text(printable, max_size=8))
number = st.one_of(st.sampled_from(FRAMES), st.integers(-10, 3000), st.floats(allow_nan=True), text_cell)
frame_number = st.one_of(*[st.integers(0, 29)] * 20, st.sampled_from(FRAMES))
"""Frame numbers of a shaped document: mostly inside a 30-frame clip, sometimes at or past the bounds."""


def file_bytes(text: st.SearchStrategy[str]) -> st.SearchStrategy[bytes]:
    """The file's bytes: a shaped text (UTF-8, sometimes with a BOM or cut short) or random bytes."""
    shaped = st.builds(
        lambda t, bom, cut: (b"\xef\xbb\xbf" if bom else b"") + t.encode("utf-8", "surrogatepass")[:cut],
        text,
        st.booleans(),
        st.one_of(st.none(), st.none(), st.none(), st.integers(1, 20_000)),
    )
    return st.one_of(shaped, shaped, shaped, st.binary(max_size=400))


def only_format_errors(read, path: Path, data: bytes) -> None:
    path.write_bytes(data)
    try:
        read(path)
    except FormatError:
        pass


def pick(draw, chaos: bool, real: st.SearchStrategy, odd: st.SearchStrategy) -> object:
    """A value from ``real``; in a chaotic document, one time in three from ``odd``."""
    return draw(st.one_of(real, real, odd) if chaos else real)


# --------------------------------------------------------------------------------------------- CVAT XML
def element(tag: str, value: object) -> str:
    return f"<{tag}>{escape(str(value))}</{tag}>"


ODD_SIZES = st.one_of(st.sampled_from([1, 0, 3_456_001, 2 * 10**9]), number)
META_FIELDS = (
    ("id", st.integers(0, 99), number),
    ("name", st.just("rally 7"), text_cell),
    ("size", st.sampled_from([30, 30, 30, 41]), ODD_SIZES),
    ("start_frame", st.sampled_from([0, 0, 10]), number),
    ("frame_filter", st.sampled_from(["", "", "step=1", "step=2"]), st.one_of(st.just("step=0"), text_cell)),
)


@st.composite
def cvat_meta(draw, chaos: bool) -> tuple[str, int, int]:
    """``<meta>`` of a task or a job export (``original_size`` inside ``<task>``, after ``</job>``), and
    the export's first video frame and frame step (so a clean document's shapes lie on its frames)."""
    kind = pick(draw, chaos, st.sampled_from(["task", "job"]), st.sampled_from(["project", "other", "task"]))
    fields, first, step = [], 0, 1
    for tag, real, odd in META_FIELDS:
        if not chaos or draw(st.integers(0, 5)):
            fields.append(element(tag, value := pick(draw, chaos, real, odd)))
            first = value if tag == "start_frame" and isinstance(value, int) else first
            step = int(value[-1]) if tag == "frame_filter" and value in ("step=1", "step=2") else step
    if kind == "job":
        start = element("start", pick(draw, chaos, st.sampled_from([0, 0, 5]), number))
        fields.append(f"<segments><segment>{start}{element('stop', 29)}</segment></segments>")
    size = ""
    if not chaos or draw(st.integers(0, 5)):
        width = pick(draw, chaos, st.sampled_from([1280, 1920]), number)
        height = pick(draw, chaos, st.sampled_from([720, 1080]), number)
        size = f"<original_size>{element('width', width)}{element('height', height)}</original_size>"
    inside = kind != "job" if not chaos else draw(st.booleans())
    body = "".join(fields) + (size if inside else "")
    node = f"<{kind}>{body}</{kind}>"
    if kind == "project":
        node = f"<project><tasks><task>{body}</task></tasks></project>"
    return f"<meta>{node}<dumped>2024</dumped>{'' if inside else size}</meta>", first, step


COORDS = {"points": ["points"], "ellipse": ["cx", "cy"], "box": ["xtl", "ytl", "xbr", "ybr"]}
XY = st.sampled_from(["640,360", "1,1", "0,0", "1280,720", "1281,0", "100.5,719.99", "33,44", "700,20"])
ONE = st.sampled_from(["640", "0", "1", "719.5", "20", "300", "-0.5"])


@st.composite
def cvat_shape(draw, chaos: bool, frame: int) -> str:
    """One shape of a track on ``frame`` (a chaotic one may have any attribute wrong or missing)."""
    shapes = st.sampled_from(["points", "points", "ellipse", "box"])
    tag = pick(draw, chaos, shapes, st.sampled_from(["polygon", "skeleton", "points"]))
    attrs = {
        "frame": pick(draw, chaos, st.just(frame), number),
        "keyframe": pick(draw, chaos, st.sampled_from(["1", "1", "0"]), text_cell),
        "outside": pick(draw, chaos, st.sampled_from(["0", "0", "0", "1"]), text_cell),
        "occluded": pick(draw, chaos, st.sampled_from(["0", "0", "1"]), text_cell),
    }
    xy, one = XY, ONE
    if chaos:
        xy = st.one_of(xy, st.sampled_from(["1300,5", "5,5;6,6", "-9,0"]))
        one = st.one_of(one, st.just("1300"))
    for name in COORDS.get(tag, ["points"]):
        attrs[name] = pick(draw, chaos, xy if name == "points" else one, text_cell)
    if chaos:
        for name in draw(st.lists(st.sampled_from(list(attrs)), max_size=2)):
            attrs.pop(name, None)
    inner = ""
    if draw(st.integers(0, 3)) == 0:
        value = pick(draw, chaos, st.sampled_from(["1", "2", "3"]), st.sampled_from(["0", "x", "", "4"]))
        inner = f'<attribute name="visibility">{escape(value)}</attribute>'
    return f"<{tag} " + " ".join(f"{k}={quoteattr(str(v))}" for k, v in attrs.items()) + f">{inner}</{tag}>"


@st.composite
def cvat_doc(draw) -> str:
    """A "CVAT for video 1.1" annotations.xml, clean or chaotic."""
    chaos = draw(st.booleans())
    parts = ['<?xml version="1.0" encoding="utf-8"?>\n<annotations>']
    parts.append(element("version", pick(draw, chaos, st.just("1.1"), st.sampled_from(["2.0", ""]))))
    first, step = 0, 1
    if not chaos or draw(st.integers(0, 8)):
        meta, first, step = draw(cvat_meta(chaos))
        parts.append(meta)
    frames = frame_number.map(lambda k: first + step * k)
    label = st.sampled_from(LABELS if chaos else BALLISH)
    for _ in range(draw(st.integers(0, 3))):
        track = draw(st.lists(frames, max_size=6, unique=not chaos))
        shapes = "".join(draw(cvat_shape(chaos, frame)) for frame in track)
        parts.append(f'<track id="0" label={quoteattr(draw(label))}>{shapes}</track>')
    for _ in range(draw(st.integers(0, 2))):
        frame = pick(draw, chaos, frames, number)
        name = draw(st.sampled_from(EVENTISH))
        parts.append(f"<tag frame={quoteattr(str(frame))} label={quoteattr(name)}/>")
    if chaos and draw(st.integers(0, 10)) == 0:
        parts.append('<image id="0"/>')
    parts.append("</annotations>\n")
    doc = "\n".join(parts)
    if chaos and draw(st.integers(0, 7)) == 0:  # a character that XML (or UTF-8) cannot hold
        at = draw(st.integers(0, len(doc)))
        doc = doc[:at] + draw(st.sampled_from(BAD_TEXT)) + doc[at:]
    return doc


@pytest.mark.filterwarnings("error::RuntimeWarning")  # a silent overflow or bad cast is a bug too
def test_cvat_import_raises_only_format_errors(tmp_path):
    labels = LabelMap.parse(["pelota=ball", "player=ignore"])

    @FUZZ
    @given(data=file_bytes(cvat_doc()), size=st.sampled_from([None, (1280, 720)]))
    def run(data: bytes, size: tuple[int, int] | None) -> None:
        only_format_errors(lambda p: import_cvat(p, labels, size=size), tmp_path / "annotations.xml", data)

    run()


# ------------------------------------------------------------------------------------- Label Studio JSON
scalar = st.one_of(st.none(), st.booleans(), st.sampled_from(FRAMES), st.integers(-10, 200),
                   st.floats(allow_nan=True), text_cell, st.just(10**400))
junk = st.recursive(
    scalar,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=8,
)
ls_frame = frame_number.map(lambda f: f + 1 if f >= 0 else f)  # Label Studio counts from 1
percent = st.floats(0, 95)


@st.composite
def keyframe(draw, chaos: bool) -> dict:
    """A ``videorectangle`` sequence item."""
    item = {
        "frame": pick(draw, chaos, ls_frame, junk),
        "enabled": pick(draw, chaos, st.booleans(), junk),
        "x": pick(draw, chaos, percent, st.one_of(st.floats(-2, 102), junk)),
        "y": pick(draw, chaos, percent, st.one_of(st.floats(-2, 102), junk)),
        "width": pick(draw, chaos, st.floats(0, 5), junk),
        "height": pick(draw, chaos, st.floats(0, 5), junk),
        "time": pick(draw, chaos, st.floats(0, 100), junk),
    }
    droppable = ["width", "height", "time", "enabled", "frame"][: 5 if chaos else 4]
    for key in draw(st.lists(st.sampled_from(droppable), max_size=2)):
        item.pop(key, None)
    return item


@st.composite
def span(draw, chaos: bool) -> dict:
    """A timeline range ``{start, end}`` (in a chaotic document possibly backwards or junk)."""
    start = draw(ls_frame)
    end = start + draw(st.sampled_from([0, 0, 0, 1, 3]))
    if chaos and draw(st.booleans()):
        end = draw(st.one_of(ls_frame, junk))
    return {"start": start, "end": end}


@st.composite
def region(draw, chaos: bool) -> dict:
    """A result region: a tracked box, a timeline label, or something else."""
    kinds = ["videorectangle", "timelinelabels", "videorectangle", "timelinelabels", "x"]
    kind = draw(st.sampled_from(kinds))
    if kind == "timelinelabels":
        ranges = pick(draw, chaos, st.lists(span(chaos), min_size=1, max_size=3), junk)
        value = {"ranges": ranges, "timelinelabels": [draw(st.sampled_from(EVENTISH))]}
    elif kind == "videorectangle":
        odd_count = st.one_of(st.sampled_from([0, 3_456_001, 2 * 10**9]), junk)
        sequence = st.lists(keyframe(chaos), max_size=5, unique_by=lambda k: str(k.get("frame")))
        value = {
            "framesCount": pick(draw, chaos, st.sampled_from([50, 50, 41, 1]), odd_count),
            "duration": pick(draw, chaos, st.sampled_from([2.0, 1.64, 5.425]), st.sampled_from([0, 1e-320])),
            "labels": pick(draw, chaos, st.lists(st.sampled_from(BALLISH), min_size=1, max_size=2), junk),
            "sequence": pick(draw, chaos, sequence, junk),
        }
        for key in draw(st.lists(st.sampled_from(["framesCount", "duration", "labels"]), max_size=1)):
            value.pop(key, None)
    else:
        keys = st.sampled_from(["labels", "x", "ranges", "sequence"])
        value = draw(st.dictionaries(keys, junk, max_size=2))
    return {"id": draw(st.text(max_size=4)), "type": kind, "value": pick(draw, chaos, st.just(value), junk)}


@st.composite
def ls_task(draw) -> dict:
    """One task of a Label Studio JSON export, clean or chaotic."""
    chaos = draw(st.booleans())
    result = st.lists(region(chaos), max_size=4)
    annotation = st.fixed_dictionaries({
        "id": st.integers(0, 3),
        "was_cancelled": st.sampled_from([False, False, True]),
        "result": st.one_of(result, junk) if chaos else result,
    })
    annotations = st.lists(annotation, min_size=1, max_size=2)
    data = st.fixed_dictionaries({"video": st.just("/data/v.mp4"), "fps": st.sampled_from([25, 24, 30.0])})
    odd_data = st.one_of(junk, st.fixed_dictionaries({"fps": st.sampled_from([0, 2000, 1e-300])}))
    task = {
        "id": pick(draw, chaos, st.integers(0, 3), junk),
        "data": pick(draw, chaos, data, odd_data),
        "annotations": pick(draw, chaos, annotations, junk),
        "predictions": pick(draw, chaos, annotations, junk),
        "meta": {"rally3d": {"width": pick(draw, chaos, st.just(1280), junk),
                             "height": pick(draw, chaos, st.just(720), junk)}},
    }
    droppable = ["predictions", "meta", "data", "annotations"][: 4 if chaos else 3]
    for key in draw(st.lists(st.sampled_from(droppable), max_size=2)):
        task.pop(key, None)
    return task


ls_doc = st.one_of(
    st.lists(ls_task(), min_size=1, max_size=1).map(json.dumps),
    st.lists(ls_task(), min_size=1, max_size=1).map(json.dumps),
    st.lists(ls_task(), max_size=3).map(json.dumps),
    ls_task().map(json.dumps),
    st.tuples(ls_task(), st.sampled_from(BAD_TEXT)).map(lambda t: json.dumps(t[0]).replace("ball", t[1], 1)),
    junk.map(json.dumps),
    st.text(max_size=200),
)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_labelstudio_import_raises_only_format_errors(tmp_path):
    choice = {"task": st.sampled_from([None, None, 0, 1]), "annotation": st.sampled_from([None, None, 1])}

    @FUZZ
    @given(data=file_bytes(ls_doc), **choice)
    def run(data: bytes, task: int | None, annotation: int | None) -> None:
        read = lambda p: import_labelstudio(p, task=task, annotation=annotation)  # noqa: E731
        only_format_errors(read, tmp_path / "export.json", data)

    run()


# ----------------------------------------------------------------------------------- the whole import
@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_import_into_a_clip_raises_only_format_errors(tmp_path):
    """``rally3d import``'s path: read the file, then write ball.csv/events.csv/clip.yaml of a new clip."""

    @settings(FUZZ, max_examples=FUZZ.max_examples if N else 40)
    @given(xml=file_bytes(cvat_doc()), js=file_bytes(ls_doc), cvat=st.booleans())
    def run(xml: bytes, js: bytes, cvat: bool) -> None:
        clip = tmp_path / "clip"
        shutil.rmtree(clip, ignore_errors=True)
        path = tmp_path / ("a.xml" if cvat else "a.json")
        path.write_bytes(xml if cvat else js)
        try:
            imported = import_cvat(path) if cvat else import_labelstudio(path, task=1)
            imported.width, imported.height = imported.width or 1280, imported.height or 720
            write_into_clip(clip, imported, sport="padel", fps=25.0)
        except FormatError:
            pass

    run()
