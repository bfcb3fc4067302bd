"""The browser side of frame playback: frames kept in the page, a step is one swap in one render.

viser re-sends and re-decodes an image node's JPEG each time it changes, so a server-driven step costs a
round trip, a decode and a texture upload after the key, and a held key lags. This script (our own code,
never built from file contents) keeps the frames in the page instead:

- **a frame feed**: the server sends each frame once, compressed (``put``); the page decodes the frames
  around the cursor ahead of time (``createImageBitmap``, off the main thread) and keeps the decoded ones
  as textures already uploaded to the GPU (labeler) or as bitmaps (review), within a budget of pixels;
  the page asks the server for the frames it lacks around the cursor (``want`` in its reports);
- **the labeler's plane**: the texture of viser's frame plane (the scene node ``/frames/0``) is swapped by
  the page and one render is requested: the step shows the new frame in a single render, with no
  intermediate picture. J/L (Shift: ×10) step in the page; holding J or L (or Space) plays at the clip's
  frame rate up to 60 fps, showing the newest frame ready and dropping the others rather than lagging.
  The page then tells the server the frame shown (for overlays, status line and labels);
- **the review's clock**: one clock in the page decides the video frame drawn in the video panel (a canvas
  of ours) and moves the 3D ball to the same frame in the same animation frame (see
  :mod:`labeler.review.app`).

The page talks to the server through a hidden text field of the GUI (``GuiUpdateMessage``, the message a
GUI input sends), one JSON report at a time. viser's scene objects are reached through its React context
(``ViewerContext``: ``nodeRefFromName``, ``requestRender``, ``sendMessage``); when that is not found (a
viser whose internals differ), nothing is attached and the server keeps stepping as before (one JPEG per
step), so the labeler still works, only slower.
"""
from __future__ import annotations

import base64
import json

PLAYER_JS = r"""
(function () {
  if (window.__r3dPlayer) return;
  const P = window.__r3dPlayer = {active: false, token: null, entries: new Map(), seq: 0};
  const isField = (t) => t instanceof HTMLElement &&
    (t.tagName === "INPUT" || t.tagName === "TEXTAREA" || t.isContentEditable);
  const now = () => performance.now();

  // viser's mutable viewer state (scene, camera, nodeRefFromName, requestRender, sendMessage), found through
  // the React fiber of its canvas: the value of the ViewerContext provider above it
  P.viewer = () => {
    const canvas = document.querySelector('canvas[data-engine^="three.js"]');
    if (!canvas) return null;
    if (P._viewer && P._viewer.canvas === canvas) return P._viewer;
    const key = Object.keys(canvas).find((k) => k.startsWith("__reactFiber$"));
    for (let f = key ? canvas[key] : null; f; f = f.return) {
      const v = f.memoizedProps && f.memoizedProps.value;
      if (v && v.mutable && v.mutable.current && v.mutable.current.canvas === canvas) {
        P._viewer = v.mutable.current;
        return P._viewer;
      }
    }
    return null;
  };
  P.render = () => { const m = P.viewer(); if (m) m.requestRender(); };

  P.reset = () => {
    for (const e of P.entries.values()) P.drop(e, true);
    P.entries = new Map();
    P.active = false; P.playing = null; P.current = null; P.requested = new Map(); P.decoding = 0;
  };
  P.reset();

  // ----------------------------------------------------------------------------------------- attach
  // cfg: {token, kind: "plane" | "review", channel (uuid of the hidden text field), lo, hi (frames), fps,
  // first, ahead, behind, budget_px (decoded pixels kept), max_blobs, width, height, speed, loop;
  // plane: node; review: ball (node name), ball_xyz (per frame from `offset`, null = no ball)}
  P.attach = (cfg) => {
    P.reset();
    P.cfg = cfg; P.token = cfg.token; P.shown = cfg.first; P.goal = cfg.first; P.dir = 1;
    P.speed = cfg.speed || 1.0; P.lastScale = 1;
    let tries = 0;
    const go = () => {
      if (P.cfg !== cfg) return;
      const ok = cfg.kind === "plane" ? P.attachPlane(cfg) : P.attachReview(cfg);
      if (!ok) { if (++tries < 400) setTimeout(go, 50); return; }
      P.active = true;
      P.report(true);
    };
    go();
  };

  P.attachPlane = (cfg) => {
    const m = P.viewer();
    const root = m && m.nodeRefFromName[cfg.node];
    let mesh = null;
    if (root) root.traverse((o) => { if (!mesh && o.isMesh && o.material && o.material.map) mesh = o; });
    if (!mesh) return false;
    P.mesh = mesh; P.template = mesh.material.map;
    // every render draws our texture, whatever viser's own props say; the renderer is kept for uploads
    mesh.onBeforeRender = (renderer) => {
      P.renderer = renderer;
      if (P.current && P.current.tex && mesh.material.map !== P.current.tex) mesh.material.map = P.current.tex;
      if (!P.playing) P.sharpen();  // the view was zoomed: more pixels for the frame shown
    };
    return true;
  };

  // ------------------------------------------------------------------------------------- the frames
  P.entry = (f) => { let e = P.entries.get(f); if (!e) { e = {f}; P.entries.set(f, e); } return e; };
  P.ready = (f) => { const e = P.entries.get(f); return !!(e && (e.tex || (P.cfg.kind !== "plane" && e.bitmap))); };
  P.drop = (e, all) => {
    if (e === P.current && !all) return;
    if (e.tex) { e.tex.dispose(); e.tex = null; }
    if (e.bitmap) { e.bitmap.close(); e.bitmap = null; }
    if (all) e.blob = null;
  };
  P.put = (token, f, b64) => {
    if (token !== P.token) return;
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    P.entry(f).blob = new Blob([bytes], {type: "image/jpeg"});
    P.requested.delete(f);
    P.prepare();
  };
  // frames wanted around the cursor, most wanted first: the cursor, then ahead in the direction, one behind, ...
  // while playing: the frames from a little ahead of the clock (those due now arrive late) to `ahead`, then
  // those due now, then those between the frame shown and the clock (late, but shown if they come first)
  const LEAD = 4;
  P.window = () => {
    const c = P.cfg, d = P.dir >= 0 ? 1 : -1, g = P.goal;
    let out = [];
    if (P.playing) {
      for (let k = LEAD; k <= c.ahead; k++) out.push(g + d * k);
      for (let k = 0; k < LEAD; k++) out.push(g + d * k);
      for (let f = g - d; (f - P.shown) * d > 0; f -= d) out.push(f);
      if (c.loop && d > 0) out = out.map((f) => (f > c.hi ? c.lo + (f - c.hi - 1) % (c.hi - c.lo + 1) : f));
    } else {
      out.push(g);
      for (let k = 1; k <= Math.max(c.ahead, c.behind); k++) {
        if (k <= c.ahead) out.push(g + d * k);
        if (k <= c.behind) out.push(g - d * k);
      }
    }
    return out.filter((f) => f >= c.lo && f <= c.hi);
  };
  P.prepare = () => {
    if (!P.cfg) return;
    const order = P.window();
    const px = P.cfg.width * P.cfg.height * P.lastScale * P.lastScale;  // pixels of a decoded frame
    const keep = new Set(order.slice(0, Math.max(4, Math.floor(P.cfg.budget_px / px))));
    if (P.current) keep.add(P.current.f);
    // forget decoded frames far from the cursor or with fewer pixels than a zoom needs, then compressed
    // ones beyond the budget
    const need = P.scaleNeeded();
    for (const e of P.entries.values()) {
      if ((e.tex || e.bitmap) && (!keep.has(e.f) || (e.scale < need && !e.loading))) P.drop(e, false);
    }
    if (P.entries.size > P.cfg.max_blobs) {
      const far = Array.from(P.entries.values()).sort((a, b) => Math.abs(b.f - P.goal) - Math.abs(a.f - P.goal));
      for (const e of far.slice(0, P.entries.size - P.cfg.max_blobs)) {
        if (e === P.current) continue;
        P.drop(e, true); P.entries.delete(e.f);
      }
    }
    const soonest = P.playing ? Array.from(keep).sort((a, b) => (a - b) * P.dir) : order;
    for (const f of soonest) {
      if (P.decoding >= 2) break;
      if (!keep.has(f)) break;
      const e = P.entries.get(f);
      if (!e || !e.blob || e.loading || e.tex || e.bitmap) continue;
      P.decode(e);
    }
  };
  // the share of the frame's pixels the view needs (1/8 steps): a 1080p frame fitted into a canvas 1000
  // pixels wide needs about half of them, so it is decoded, uploaded and drawn at that size (software WebGL
  // pays per pixel); zoomed in, all of them
  P.scaleNeeded = () => {
    if (P.cfg.kind !== "plane" || !P.mesh) return 1;
    const m = P.viewer(), cam = m && m.camera;
    if (!cam || !m.canvas || !cam.fov) return 1;
    const local = P.mesh.worldToLocal(cam.getWorldPosition(cam.position.clone()));
    const d = Math.abs(local.z);
    if (!(d > 1e-6)) return 1;
    const screenH = m.canvas.height * P.cfg.render_height / (2 * d * Math.tan(cam.fov * Math.PI / 360));
    return Math.min(1, Math.ceil(8 * 1.15 * screenH / P.cfg.height) / 8);
  };
  P.decode = (e) => {
    e.loading = true; P.decoding += 1;
    const token = P.token, scale = P.scaleNeeded();
    const opts = {};
    if (P.cfg.kind === "plane") opts.imageOrientation = "flipY";  // WebGL does not flip ImageBitmaps on upload
    if (scale < 1) {
      opts.resizeWidth = Math.max(16, Math.round(P.cfg.width * scale));
      opts.resizeHeight = Math.max(16, Math.round(P.cfg.height * scale));
      opts.resizeQuality = "medium";
    }
    createImageBitmap(e.blob, opts).then((bm) => {
      e.loading = false; P.decoding -= 1;
      if (token !== P.token || !P.entries.has(e.f)) { bm.close(); return; }
      const sharper = !!(e.tex || e.bitmap);  // a zoom asked for more pixels: replace the picture
      if (e.bitmap) e.bitmap.close();
      e.bitmap = bm; e.scale = scale; P.lastScale = scale;
      if (P.cfg.kind === "plane") {
        const T = P.template;
        const tex = new T.constructor(bm);
        tex.colorSpace = T.colorSpace; tex.flipY = false; tex.generateMipmaps = false;
        tex.minFilter = 1006; tex.magFilter = 1006;  // THREE.LinearFilter: no mipmaps to build per frame
        tex.needsUpdate = true;
        if (P.renderer && P.renderer.initTexture) P.renderer.initTexture(tex);  // upload now, not on the key
        const old = e.tex;
        e.tex = tex;
        if (sharper && P.current === e) { P.mesh.material.map = tex; P.render(); }
        if (old) old.dispose();
      }
      if (!sharper && e.f === P.goal && P.shown !== e.f && !P.playing) P.show(e.f);
      P.prepare();
    }, (err) => { e.loading = false; P.decoding -= 1; if (!e.tex) e.blob = null; P.failed = String(err); P.prepare(); });
  };
  P.sharpen = () => {  // the frame shown, decoded again with the pixels a zoom needs
    const e = P.current;
    if (e && e.blob && !e.loading && e.scale !== undefined && e.scale < P.scaleNeeded()) P.decode(e);
  };

  // ------------------------------------------------------------------------------------ the cursor
  P.clamp = (f) => Math.max(P.cfg.lo, Math.min(P.cfg.hi, Math.round(f)));
  P.show = (f) => {
    const e = P.entries.get(f);
    if (!e || !P.ready(f)) return false;
    P.current = e; P.shown = f;
    if (P.cfg.kind === "plane") { P.mesh.material.map = e.tex; P.render(); }
    else P.drawReview(e);
    P.report(false);
    return true;
  };
  P.goto = (f) => {
    if (!P.active) return;
    f = P.clamp(f);
    if (f !== P.goal) P.dir = f > P.goal ? 1 : -1;
    P.goal = f;
    if (!P.show(f)) P.report(true);  // not in the page yet: ask for it now; shown once decoded
    P.prepare();
  };
  P.step = (d) => P.goto(P.goal + d);

  P.play = (dir, speed) => {
    if (!P.active) return;
    P.playing = {dir: dir >= 0 ? 1 : -1, t0: now(), f0: P.shown, speed: speed || P.speed};
    P.dir = P.playing.dir;
    P.report(true);
    requestAnimationFrame(P.tick);
  };
  P.stop = () => {
    if (!P.playing) return;
    P.playing = null; P.goal = P.shown;
    P.report(true);
  };
  // the server's play / pause, numbered: reports say which command they follow (the server ignores the
  // `playing` of reports sent before its latest command arrived)
  P.setPlaying = (on, cmd) => {
    if (cmd) P.cmd = cmd;
    if (on && !P.playing) P.play(1, P.speed); else if (!on) P.stop(); else P.report(true);
  };
  P.setSpeed = (s) => { P.speed = s; if (P.playing) P.play(P.playing.dir, s); };
  P.tick = () => {
    const pl = P.playing;
    if (!pl) return;
    const rate = Math.min(P.cfg.fps * pl.speed, 60);
    const lo = P.cfg.lo, hi = P.cfg.hi;
    let due = pl.f0 + pl.dir * Math.floor((now() - pl.t0) * rate / 1000);
    if (P.cfg.loop && due > hi) { pl.t0 = now(); pl.f0 = lo; due = lo; }  // the review loops over the rally
    const want = P.clamp(due);
    P.goal = want;
    // the newest frame ready between the one shown and the one due: frames not ready are dropped
    if (want !== P.shown) {
      const ahead = (want - P.shown) * pl.dir > 0;  // false after a loop's wrap
      const stopAt = ahead ? P.shown : (pl.dir > 0 ? lo - 1 : hi + 1);
      for (let f = want; f !== stopAt; f -= pl.dir) if (P.ready(f)) { P.show(f); break; }
    }
    P.prepare();
    P.report(false);
    const end = pl.dir > 0 ? hi : lo;
    if (!P.cfg.loop && want === end && P.shown === end) { P.stop(); return; }
    requestAnimationFrame(P.tick);
  };

  // ----------------------------------------------------------------------------- talking to the server
  // a report: the frame shown, the cursor, the direction, playing or not, and the frames wanted (not in the
  // page, not asked for in the last 3 s; at most 8 at a time)
  P.report = (force) => {
    if (!P.active) return;
    const t = now();
    if (!force && t - (P._sent || 0) < 100) {
      if (!P._later) P._later = setTimeout(() => { P._later = null; P.report(true); }, 100);
      return;
    }
    P._sent = t;
    const want = [];
    let inflight = 0;
    for (const [f, at] of P.requested) { if (t - at > 3000) P.requested.delete(f); else inflight += 1; }
    for (const f of P.window()) {
      if (inflight + want.length >= (P.playing ? 2 * P.cfg.ahead : 8)) break;
      const e = P.entries.get(f);
      if ((e && e.blob) || P.requested.has(f)) continue;
      want.push(f); P.requested.set(f, t);
    }
    const m = P.viewer();
    if (!m) return;
    P.seq += 1;
    const msg = {seq: P.seq, token: P.token, shown: P.shown, goal: P.goal, dir: P.dir,
                 playing: !!P.playing, cmd: P.cmd || 0, want: want};
    m.sendMessage({type: "GuiUpdateMessage", uuid: P.cfg.channel, updates: {value: JSON.stringify(msg)}});
  };

  // ----------------------------------------------------------------------------------------- keys
  // J/L step (Shift: 10), held J/L play in that direction, Space plays or pauses; only with the page's
  // frames attached (otherwise viser's hotkeys reach the server as before), never while typing in a field
  const HOLD_MS = 350;
  const stepOf = (ev) => {
    const k = (ev.key || "").toLowerCase();
    if (k === "l") return ev.shiftKey ? 10 : 1;
    if (k === "j") return ev.shiftKey ? -10 : -1;
    return 0;
  };
  window.addEventListener("keydown", (ev) => {
    if (!P.active || P.cfg.kind !== "plane" || isField(ev.target) || ev.ctrlKey || ev.metaKey || ev.altKey) return;
    const d = stepOf(ev);
    if (!d && ev.key !== " ") return;
    ev.preventDefault(); ev.stopImmediatePropagation();
    if (ev.key === " ") { if (!ev.repeat) P.playing ? P.stop() : P.play(1, P.speed); return; }
    if (ev.repeat) return;                       // a held key plays (below), its auto-repeats are not steps
    P.stop();
    P.step(d);
    clearTimeout(P._hold);
    if (Math.abs(d) === 1) P._hold = setTimeout(() => { P._held = true; P.play(d, P.speed); }, HOLD_MS);
  }, true);
  window.addEventListener("keyup", (ev) => {
    if (!P.active || P.cfg.kind !== "plane") return;
    const k = (ev.key || "").toLowerCase();
    if (k !== "l" && k !== "j") return;
    clearTimeout(P._hold);
    if (P._held) { P._held = false; P.stop(); }
  }, true);
  window.addEventListener("blur", () => { clearTimeout(P._hold); if (P._held) { P._held = false; P.stop(); } });

  // ---------------------------------------------------------------------------------------- review
  // the video panel's <img> (viser's GUI image) gives way to a canvas of ours; the ball node of the 3D view
  // moves with the video frame drawn
  P.attachReview = (cfg) => {
    const m = P.viewer();
    const ball = m && m.nodeRefFromName[cfg.ball];
    const img = Array.from(document.querySelectorAll("img")).find((i) => i.naturalWidth === cfg.width);
    if (!ball || !img) return false;
    // our own elements beside viser's <img> (kept across a re-attach): the caption, then the video canvas
    const own = (tag, cls, css, before) => {
      let el = img.parentElement.querySelector(tag + "." + cls);
      if (!el) {
        el = document.createElement(tag);
        el.className = cls; el.style.cssText = css;
        img.parentElement.insertBefore(el, before);
      }
      return el;
    };
    const canvas = own("canvas", "r3d-video", "max-width:100%;height:auto;display:none", img);
    const caption = own("div", "r3d-caption", "font-weight:600;font-size:0.9em;padding:0 0 0.3em 0", canvas);
    P.img = img;
    P.caption = caption;
    canvas.width = cfg.width; canvas.height = cfg.height;
    let mesh = null;  // viser sets the node's own visibility every render: hide and show the mesh inside
    ball.traverse((o) => { if (!mesh && o.isMesh) mesh = o; });
    if (!mesh) return false;
    P.video = canvas; P.ctx = canvas.getContext("2d"); P.ball = ball; P.ballMesh = mesh; P.shown3d = -1;
    return true;
  };
  P.drawReview = (e) => {
    P.ctx.drawImage(e.bitmap, 0, 0);
    if (P.video.style.display === "none") { P.video.style.display = "block"; P.img.style.display = "none"; }
    const xyz = P.cfg.ball_xyz[e.f - P.cfg.offset];
    if (xyz) { P.ball.position.set(xyz[0], xyz[1], xyz[2]); P.ballMesh.visible = true; }
    else P.ballMesh.visible = false;
    P.shown3d = e.f;
    P.caption.textContent = "frame " + e.f + P.cfg.caption;
    P.render();
  };
})();
"""


def queue_js(client, source: str) -> None:
    """Run ``source`` in one viser client's page (viser's ``RunJavascriptMessage``)."""
    from viser import _messages

    client.gui._websock_interface.queue_message(_messages.RunJavascriptMessage(source=source))


def install_player(client) -> None:
    """Send :data:`PLAYER_JS` to one client (idempotent in the page)."""
    queue_js(client, PLAYER_JS)


def call_player(client, method: str, *args) -> None:
    """Call ``window.__r3dPlayer.<method>(*args)`` in the page; the arguments travel as JSON."""
    if not method.isidentifier():
        raise ValueError(f"not a player method: {method!r}")
    queue_js(client, f"window.__r3dPlayer && window.__r3dPlayer.{method}({', '.join(json.dumps(a) for a in args)});")


def put_frame_js(token: str, frame: int, jpeg: bytes) -> str:
    """The page call that hands it one compressed frame."""
    return (f"window.__r3dPlayer && window.__r3dPlayer.put({json.dumps(token)}, {int(frame)}, "
            f"\"{base64.b64encode(jpeg).decode('ascii')}\");")
