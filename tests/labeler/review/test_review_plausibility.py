"""A review that never overstates: shots over a failed flight (or without 3D) show no figure and no call,
a clip that is not plausible (or not judged) says so first, and a call within 2σ of its line says it is too
close to call. Clip folders are the reconstructed sample, edited here (segments.json, ball_3d.csv)."""
from __future__ import annotations

import csv
import html
import io
import json
import math
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from review_fixtures import reconstructed_clip, sample_shots  # noqa: F401  (fixture)

from inference.clipio import Clip
from inference.court import load_court
from labeler.review.cli import shots_table
from labeler.review.data import ReviewData
from labeler.review.export import export_review
from labeler.review.panels import (
    banner_html,
    current_shot_markdown,
    populate_banner,
    shot_cells,
    shots_markdown,
)
from labeler.review.shots import (
    CSV_COLUMNS,
    Contact,
    CourtRules,
    Plausibility,
    analyse_clip,
    call_text,
    judge_shot,
    shot_rows,
)

R = 0.0328
SCRIPT = "<script>window.__pwned=1</script>"
OLD_COLUMNS = ("shot", "team", "serve", "hit_frame", "end_frame", "hit_x_m", "hit_y_m", "hit_z_m",
               "launch_speed_kmh", "max_speed_kmh", "net_clearance_m", "bounce_frame", "bounce_x_m",
               "bounce_y_m", "bounce_speed_kmh", "call", "line_distance_cm", "nearest_line", "target",
               "verdict", "reason", "contacts")


# -------------------------------------------------------------------------------------------- helpers
def copy_clip(src: Path, dest: Path) -> Path:
    return Path(shutil.copytree(src, dest))


def edit_segments(clip: Path, edit) -> None:
    """Apply ``edit(doc)`` to the clip's segments.json in place."""
    path = clip / "segments.json"
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc, indent=1))


def fail_flight(doc: dict, index: int, reason: str) -> None:
    """Mark flight ``index`` failed as the pipeline writes it: ``reconstructed`` false, a reason, no fit."""
    for s in doc["segments"]:
        if s["index"] == index:
            keep = ("index", "start_frame", "end_frame", "start_event", "end_event")
            for k in [k for k in s if k not in keep]:
                del s[k]
            s.update(reconstructed=False, reason=reason)


def not_plausible(doc: dict, because: list[str], covered: float) -> None:
    p = doc["plausibility"]
    failed = sum(not s["reconstructed"] for s in doc["segments"])
    p.update(plausible=False, not_plausible_because=because, failed=failed,
             reconstructed=p["flights"] - failed, covered_share=covered)


def edit_ball_3d(clip: Path, edit) -> None:
    """Apply ``edit(rows) -> rows`` to ball_3d.csv's rows (dicts of strings)."""
    path = clip / "ball_3d.csv"
    with path.open() as f:
        reader = csv.DictReader(f)
        fields, rows = reader.fieldnames, list(reader)
    rows = edit(rows)
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def n_flights(clip: Path) -> int:
    """The flights of the clip's segments.json (the sample's reconstruction)."""
    return len(json.loads((clip / "segments.json").read_text())["segments"])


def with_bounce(shots: list) -> list:
    """The shots of the sample that have a floor bounce to call: all but the last, which the clip's end cuts
    before its bounce (:func:`review_fixtures.sample_shots`)."""
    bounced = [b for *_, b in sample_shots()]
    assert len(shots) == len(bounced)
    return [s for s, b in zip(shots, bounced) if b]


def table_row(table: str, shot: int) -> str:
    """The printed table's row of ``shot`` (rows start with the right-aligned shot number)."""
    return next(line for line in table.splitlines() if line[:4].strip() == str(shot) and line[4:5] == " ")


@pytest.fixture(scope="module")
def failed_clip(reconstructed_clip, tmp_path_factory) -> Path:
    """Flight 3 (the far return, frames 69–98) failed; its rows are left in ball_3d.csv."""
    clip = copy_clip(reconstructed_clip, tmp_path_factory.mktemp("failed") / "clip")
    n = n_flights(clip)

    def edit(doc):
        fail_flight(doc, 3, f"passes through the net {SCRIPT}")
        not_plausible(doc, [f"1/{n} flights failed", f"odd {SCRIPT}"], 0.76)

    edit_segments(clip, edit)
    return clip


# ------------------------------------------------------------------------ (a) shots over a failed flight
def test_a_shot_over_a_failed_flight_has_no_figure_and_no_call(failed_clip, reconstructed_clip):
    rows = np.loadtxt(failed_clip / "ball_3d.csv", delimiter=",", skiprows=1, usecols=0)
    assert ((rows > 69) & (rows < 98)).sum() >= 25  # the failed flight's rows are still in ball_3d.csv
    good = analyse_clip(Clip(reconstructed_clip))
    a = analyse_clip(Clip(failed_clip))
    s = a.shots[1]
    assert s.hit.frame == 69 and not s.has_3d
    assert s.verdict == "-" and s.reason.startswith("no 3D: ") and "passes through the net" in s.reason
    assert s.no_3d.startswith("flight 69–98 failed")
    for v in (s.launch_speed_kmh, s.max_speed_kmh, s.bounce_speed_kmh, s.net_clearance_m):
        assert math.isnan(v)
    assert [b.call for b in s.bounces] == ["-"] and math.isnan(s.first_bounce.distance_cm)
    assert not np.isfinite(s.first_bounce.xy).any()
    # the neighbours keep their figures and calls
    for k in (0, 2, 3):
        assert a.shots[k].has_3d and a.shots[k].verdict == good.shots[k].verdict == "in"
        assert a.shots[k].launch_speed_kmh == good.shots[k].launch_speed_kmh
    # the printed table, the CSV and the GUI/HTML cells say why, with no figure
    row = table_row(shots_table(a), 1)
    assert "no 3D: flight 69–98 failed: passes through the net" in row
    assert f"{good.shots[1].launch_speed_kmh:.1f}" not in row and "km/h" not in row
    csv_row = shot_rows(a)[1]
    assert csv_row["status"] == "no 3D" and "passes through the net" in csv_row["no_3d_reason"]
    blank = ("launch_speed_kmh", "max_speed_kmh", "net_clearance_m", "bounce_x_m", "line_distance_cm",
             "nearest_line", "line_sigma_cm")
    assert all(csv_row[k] == "" for k in blank)
    assert csv_row["verdict"] == "-" and csv_row["call"] == "-"
    assert shot_rows(a)[0]["status"] == "ok" and shot_rows(a)[0]["no_3d_reason"] == ""
    cells = shot_cells(s)
    assert cells[2] == cells[3] == cells[4] == cells[6] == "–" and cells[5] == "-"
    assert cells[-1].startswith("no 3D: ")


def test_a_shot_without_3d_rows_says_so(reconstructed_clip, tmp_path):
    """segments.json says every flight is fine, but ball_3d.csv has no row inside shot 2 (frames 101–147):
    its bounce (placed by segments.json's fitted point) is not called."""
    clip = copy_clip(reconstructed_clip, tmp_path / "clip")
    edit_ball_3d(clip, lambda rows: [r for r in rows if not 101 < int(r["frame"]) < 147])
    s = analyse_clip(Clip(clip)).shots[2]
    assert not s.has_3d and s.reason == "no 3D: no 3D rows for frames 101–147"
    assert s.verdict == "-" and s.first_bounce.call == "-" and math.isnan(s.launch_speed_kmh)


def test_scene_labels_show_no_call_for_a_shot_without_3d(failed_clip):
    from labeler.review.scene import contact_labels

    data = ReviewData.load(failed_clip)
    texts = [lab.text for lab in contact_labels(data.analysis)]
    assert "1: no 3D @98" in texts and not any(t.startswith("1: in") or t.startswith("1: out") for t in texts)


# --------------------------------------------------------------------------------------- (b) banners
def test_b_banner_first_in_the_printed_table_and_escaped_in_replay_html(failed_clip, tmp_path, capsys):
    from inference.cli import main

    assert main(["review", str(failed_clip), "--export", str(tmp_path / "out"), "--stride", "8"]) == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert first.startswith(f"3D NOT plausible: 1/{n_flights(failed_clip)} flights failed")
    assert "calls and figures below come only from the flights that passed their checks" in first
    assert "3D covers 76% of the rally" in out.splitlines()[1]
    page = (tmp_path / "out" / "replay.html").read_text()
    start = page.index('id="rally3d-banner"')
    banner = page[start: page.index("</div>", start)]
    assert "3D NOT plausible" in banner and "3D covers 76% of the rally" in banner
    assert html.escape(SCRIPT) in banner and SCRIPT not in page  # the reason and the failed flight's, escaped
    assert page.index('id="rally3d-banner"') < page.index('id="rally3d-shots"')
    assert "no 3D: flight 69–98 failed: passes through the net" in page


def test_b_not_judged_without_a_plausibility_check(reconstructed_clip, tmp_path):
    clip = copy_clip(reconstructed_clip, tmp_path / "clip")
    plausible = ReviewData.load(clip).analysis
    n = n_flights(clip)  # every flight of segments.json, the lob above the picture included, reconstructed
    assert shots_table(plausible).splitlines()[0].startswith(f"3D plausible: {n}/{n} flights reconstructed")
    assert "NOT" not in shots_table(plausible)
    edit_segments(clip, lambda doc: doc.pop("plausibility"))
    line = shots_table(ReviewData.load(clip).analysis).splitlines()[0]
    assert line.startswith("3D NOT judged") and "no plausibility check" in line
    (clip / "segments.json").unlink()
    a = analyse_clip(Clip(clip))
    assert shots_table(a).splitlines()[0].startswith("3D NOT judged") and "segments.json" in shots_table(a)
    assert analyse_clip(Clip(clip), gt=True).plausibility is None  # ground truth needs no check


def test_b_gui_banner_is_escaped_and_first(failed_clip):
    a = ReviewData.load(failed_clip).analysis
    content = banner_html(a.plausibility)
    assert "3D NOT plausible" in content and html.escape(SCRIPT) in content and SCRIPT not in content
    calls: list[tuple[str, str]] = []
    gui = SimpleNamespace(add_html=lambda c, **_: calls.append(("html", c)) or SimpleNamespace(content=c))
    handle = populate_banner(gui, a.plausibility)
    assert calls == [("html", content)] and handle.content == content
    # the GUI's shot table and current-shot text (viser renders their HTML): the reason, escaped, no figure
    table, now = shots_markdown(a), current_shot_markdown(a, 80)
    assert "no 3D: flight 69–98 failed" in table and SCRIPT not in table and "&lt;script&gt;" in table
    assert "no 3D: flight 69–98 failed" in now and SCRIPT not in now and "km/h" not in now
    ok = Plausibility(judged=True, plausible=True, flights=13, failed=0, covered_share=1.0)
    assert "NOT" not in banner_html(ok) and "3D covers 100% of the rally" in banner_html(ok)


def test_plausibility_from_segments_json():
    p = Plausibility.from_segments_json({"segments": [], "plausibility": {
        "plausible": False, "not_plausible_because": ["4/5 flights failed", "3D for 8% of the rally only"],
        "flights": 5, "failed": 4, "covered_share": 0.08}})
    assert p.banner() == ("3D NOT plausible: 4/5 flights failed; 3D for 8% of the rally only — calls and "
                          "figures below come only from the flights that passed their checks")
    assert p.coverage() == "3D covers 8% of the rally"
    assert not Plausibility.from_segments_json(None).judged
    weird = Plausibility.from_segments_json({"plausibility": {"plausible": "yes", "covered_share": "x",
                                                              "not_plausible_because": 3}})
    assert weird.judged and not weird.plausible and weird.covered_share is None  # never reads "plausible"


# ---------------------------------------------------------------------------- (c) calls near a line
def test_c_call_within_two_sigma_says_too_close_to_call():
    padel = CourtRules.from_court(load_court("padel"))
    cov = np.diag([0.02 ** 2, 0.05 ** 2, 0.01 ** 2])  # σx 2 cm (across the side line), σy 5 cm
    _, reason, [near] = judge_shot(padel, "near", [Contact(40, "ground", (9.97, 15, R), "floor", cov)])
    assert near.call == "in" and near.line == "right side line" and near.distance_cm == pytest.approx(3)
    assert near.sigma_cm == pytest.approx(2.0) and near.uncertain
    assert call_text(near) == "in, 3 cm inside the right side line — within 2σ (±4 cm): too close to call"
    assert "too close to call" in reason
    _, reason, [far] = judge_shot(padel, "near", [Contact(40, "ground", (9.5, 15, R), "floor", cov)])
    assert far.call == "in" and far.sigma_cm == pytest.approx(2.0) and not far.uncertain
    assert "too close" not in call_text(far) + reason and "±4 cm at 2σ" in call_text(far)
    # across the baseline σ is σy: 4 cm outside with σy 5 cm is too close to call, with σx alone it was not
    _, _, [base] = judge_shot(padel, "near", [Contact(40, "ground", (5, 20.04, R), "floor", cov)])
    assert base.call == "out" and base.sigma_cm == pytest.approx(5.0) and base.uncertain
    assert call_text(base).startswith("out, 4 cm outside the far baseline — within 2σ (±10 cm)")
    # beyond a corner: σ along the diagonal
    _, _, [corner] = judge_shot(padel, "near", [Contact(40, "ground", (10.03, 20.04, R), "floor", cov)])
    n = np.array([0.03, 0.04]) / 0.05
    assert corner.sigma_cm == pytest.approx(100 * math.sqrt(n @ cov[:2, :2] @ n), abs=0.05)  # 0.1 cm steps
    _, _, [unknown] = judge_shot(padel, "near", [Contact(40, "ground", (9.97, 15, R), "floor")])
    assert math.isnan(unknown.sigma_cm) and not unknown.uncertain and "σ unknown" in call_text(unknown)


def test_c_clip_bounce_moved_next_to_a_line_is_too_close_to_call(reconstructed_clip, tmp_path):
    """The serve's bounce (frame 56, far left service box) moved to 1 cm from the centre service line, with
    σx = 2 cm in ball_3d.csv: too close to call; the other bounces, metres from their lines, are not."""
    clip = copy_clip(reconstructed_clip, tmp_path / "clip")

    def move(doc):
        for s in doc["segments"]:
            if s["end_frame"] == 56:
                s["end_point_m"][0] = 4.99
            if s["start_frame"] == 56:
                s["start_point_m"][0] = 4.99

    def widen(rows):
        for r in rows:
            if r["frame"] == "56":
                r["cov_xx_m2"], r["cov_xy_m2"], r["cov_xz_m2"] = "0.0004", "0", "0"
        return rows

    edit_segments(clip, move)
    edit_ball_3d(clip, widen)
    a = analyse_clip(Clip(clip))
    b = a.shots[0].first_bounce
    assert b.frame == 56 and b.line == "centre service line" and b.distance_cm == pytest.approx(1)
    assert b.sigma_cm == pytest.approx(2.0) and b.uncertain
    others = [s.first_bounce for s in with_bounce(a.shots)[1:]]
    assert 232 in [o.frame for o in others]  # the far lob's bounce, after 59 frames above the picture
    assert all(math.isfinite(o.sigma_cm) and not o.uncertain for o in others)
    table = shots_table(a)
    assert "within 2σ (±4 cm): too close to call" in table_row(table, 0)
    assert "too close" not in table_row(table, 1) and "at 2σ" in table_row(table, 1)
    rows = shot_rows(a)
    assert rows[0]["too_close_to_call"] == 1 and rows[0]["line_sigma_cm"] == pytest.approx(2.0)
    assert rows[1]["too_close_to_call"] == 0 and rows[-1]["too_close_to_call"] == ""  # the last: no bounce
    assert a.shots[-1].first_bounce is None
    assert "too close to call" in shot_cells(a.shots[0])[-1]
    # without its covariance at the bounce frame, the nearest frame of its flight gives it
    edit_ball_3d(clip, lambda rows: [{**r, **({c: "" for c in r if c.startswith("cov_")} if r["frame"] == "56"
                                              else {})} for r in rows])
    assert math.isfinite(analyse_clip(Clip(clip)).shots[0].first_bounce.sigma_cm)


def test_c_sigma_unknown_without_covariance_columns(reconstructed_clip, tmp_path):
    clip = copy_clip(reconstructed_clip, tmp_path / "clip")
    edit_ball_3d(clip, lambda rows: [{k: v for k, v in r.items() if not k.startswith("cov_")} for r in rows])
    a = analyse_clip(Clip(clip))
    assert all(math.isnan(s.first_bounce.sigma_cm) for s in with_bounce(a.shots))
    assert "σ unknown" in table_row(shots_table(a), 0) and "σ unknown" in shot_cells(a.shots[0])[-1]
    assert shot_rows(a)[0]["call_note"] == "σ unknown" and shot_rows(a)[0]["too_close_to_call"] == ""


# ------------------------------------------------------------------------------------ (d) shots.csv
def test_d_shots_csv_keeps_its_columns_and_adds_status_and_sigma(failed_clip, tmp_path):
    res = export_review(ReviewData.load(failed_clip), tmp_path / "out", stride=8, progress=False)
    text = res.shots_csv.read_text()
    header = tuple(next(csv.reader(io.StringIO(text))))
    assert header == CSV_COLUMNS and header[: len(OLD_COLUMNS)] == OLD_COLUMNS
    assert {"status", "no_3d_reason", "line_sigma_cm", "too_close_to_call", "call_note"} <= set(header)
    rows = list(csv.DictReader(io.StringIO(text)))
    # shot 1 (the far hit at 69) lies over the failed flight 69–98; every other shot of the sample is ok
    assert [r["status"] for r in rows] == ["no 3D" if k == 1 else "ok" for k in range(len(sample_shots()))]
    assert float(rows[0]["line_sigma_cm"]) > 0 and rows[0]["too_close_to_call"] == "0"
    assert SCRIPT in rows[1]["no_3d_reason"]  # the CSV keeps the text as it is (no HTML here)
    # what pinned each reconstructed shot's depth (segments.json's depth_from); nothing for the shot without 3D
    assert header[-1] == "depth_from" and rows[1]["depth_from"] == ""
    assert all(r["depth_from"].startswith("the ") for r in rows if r["status"] == "ok"), [r["depth_from"] for r in rows]
