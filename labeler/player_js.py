"""The browser side of frame playback: frames kept in the page, a step is one swap in one render.

viser re-sends and re-decodes an image node's JPEG each time it changes, so a server-driven step costs a
round trip, a decode and a texture upload after the key, and a held key lags. This script (our own code,
never built from file contents) keeps the frames in the page instead:

- **a frame feed**: the server sends each frame once, compressed (``put``); the page decodes the frames
  around the cursor ahead of time (``createImageBitmap``, off the main thread, at the size the view needs)
  and keeps them as bitmaps within a budget of pixels; the page asks the server for the frames it lacks
  around the cursor (``want`` in its reports);
- **the labeler's frame**: a 2D canvas of ours under viser's transparent WebGL canvas, placed by a CSS
  homography exactly where viser's frame plane (the scene node ``/frames/0``) projects, so overlays, zoom
  and pan stay as they were; the plane itself is no longer drawn (it still takes the clicks). A step draws
  one bitmap into our canvas: no WebGL render, no intermediate picture. J/L (Shift: ×10) step in the page;
  holding J or L (or Space) plays at the clip's frame rate up to 60 fps, showing the newest frame ready and
  dropping the others rather than lagging. The page then tells the server the frame shown (for overlays,
  status line and labels);
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
  // viser handles its messages inside a render of the 3D scene (except GUI-only batches), and each request
  // for one renders for a while: every frame sent to the page would re-render the scene (in software WebGL
  // the dearest work of playing). Calls to this player touch no 3D state: a batch of nothing but them and
  // GUI value updates (the status line following the page) is handled at once, as viser handles GUI-only
  // batches, without a render
  const OURS = "window.__r3dPlayer && window.__r3dPlayer.";
  const quietMessage = (msg) => !!msg && (msg.type === "GuiUpdateMessage" ||
    (msg.type === "RunJavascriptMessage" && String(msg.source).startsWith(OURS)));
  P.quiet = (m) => {
    if (m.__r3dQuiet === m.requestRender) return;
    const request = m.requestRender;
    m.requestRender = m.__r3dQuiet = function (...args) {
      const q = m.messageQueue, drain = m.drainMessageQueue;
      if (Array.isArray(q) && q.length && drain && m.getRenderRequestState === "ready" &&
          q.every(quietMessage)) {
        drain();
        return;
      }
      return request.apply(this, args);
    };
  };

  P.reset = () => {
    for (const e of P.entries.values()) P.drop(e, true);
    P.entries = new Map();
    P.active = false; P.playing = null; P.current = null; P.requested = new Map(); P.decoding = 0;
    P.drawn = undefined;
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
      P.quiet(P.viewer());
      P.report(true);
    };
    go();
  };

  // the labeler: a 2D canvas of ours under viser's (transparent) WebGL canvas, placed by a CSS homography
  // exactly where viser's frame plane projects; the plane itself is no longer drawn (it stays for clicks),
  // the overlays stay in WebGL above it. A step draws one bitmap into our canvas: no WebGL render at all
  P.attachPlane = (cfg) => {
    const m = P.viewer();
    const root = m && m.nodeRefFromName[cfg.node];
    let mesh = null;
    if (root) root.traverse((o) => { if (!mesh && o.isMesh && o.material && o.material.map) mesh = o; });
    if (!mesh || !m.scene || !m.camera) return false;
    P.mesh = mesh;
    const gl = m.canvas, wrap = gl.parentElement;
    let c = wrap.querySelector("canvas.r3d-frame");
    if (!c) {
      c = document.createElement("canvas");
      c.className = "r3d-frame";
      c.style.cssText = "position:absolute;left:0;top:0;z-index:-1;pointer-events:none;" +
        "transform-origin:0 0;visibility:hidden";
      wrap.insertBefore(c, gl);
    }
    P.frameCanvas = c; P.ctx = c.getContext("2d");
    if (!m.scene.__r3dFollows) {  // every render of viser's scene: follow its camera (hooked once per page)
      m.scene.__r3dFollows = true;
      const before = m.scene.onBeforeRender;
      m.scene.onBeforeRender = function (...args) {
        if (before) before.apply(this, args);
        if (P.active && P.cfg.kind === "plane") {
          P.place();
          if (!P.playing) P.sharpen();  // the view was zoomed: more pixels for the frame shown
        }
      };
    }
    return true;
  };

  // CSS matrix3d taking the rectangle (0, 0)-(w, h) onto the quad tl, tr, bl, br (a homography)
  const adj = (m) => [m[4] * m[8] - m[5] * m[7], m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
    m[5] * m[6] - m[3] * m[8], m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
    m[3] * m[7] - m[4] * m[6], m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3]];
  const mul = (a, b) => {
    const c = new Array(9).fill(0);
    for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) c[3 * i + j] += a[3 * i + k] * b[3 * k + j];
    return c;
  };
  const basis = (p) => {
    const m = [p[0][0], p[1][0], p[2][0], p[0][1], p[1][1], p[2][1], 1, 1, 1];
    const a = adj(m), v = [p[3][0], p[3][1], 1];
    const s = [0, 1, 2].map((i) => a[3 * i] * v[0] + a[3 * i + 1] * v[1] + a[3 * i + 2] * v[2]);
    return mul(m, [s[0], 0, 0, 0, s[1], 0, 0, 0, s[2]]);
  };
  P.matrix3d = (w, h, quad) => {
    const t = mul(basis(quad), adj(basis([[0, 0], [w, 0], [0, h], [w, h]])));
    const n = t.map((v) => v / t[8]);
    return `matrix3d(${n[0]},${n[3]},0,${n[6]},${n[1]},${n[4]},0,${n[7]},0,0,1,0,${n[2]},${n[5]},0,1)`;
  };
  // where viser's plane is on screen now (CSS px of its canvas): the quad tl, tr, bl, br, or null
  P.quad = () => {
    const m = P.viewer(), g = P.mesh.geometry.parameters, gl = m.canvas;
    const V = P.mesh.position.constructor, quad = [];
    for (const [x, y] of [[-1, 1], [1, 1], [-1, -1], [1, -1]]) {
      const v = new V(x * g.width / 2, y * g.height / 2, 0);
      P.mesh.localToWorld(v);
      v.project(m.camera);
      if (!(v.z < 1)) return null;   // behind the camera
      quad.push([(v.x + 1) / 2 * gl.clientWidth, (1 - v.y) / 2 * gl.clientHeight]);
    }
    return quad;
  };
  P.place = () => {
    const c = P.frameCanvas;
    if (!c || !P.mesh || P.drawn === undefined) return;
    const quad = P.quad();
    if (!quad) { c.style.visibility = "hidden"; return; }
    c.style.transform = P.matrix3d(c.width, c.height, quad);
    c.style.visibility = "visible";
    if (P.mesh.material.visible) { P.mesh.material.visible = false; P.render(); }  // ours shows the frame now
  };

  // ------------------------------------------------------------------------------------- the frames
  P.entry = (f) => { let e = P.entries.get(f); if (!e) { e = {f}; P.entries.set(f, e); } return e; };
  P.ready = (f) => { const e = P.entries.get(f); return !!(e && e.bitmap); };
  P.drop = (e, all) => {
    if (e === P.current && !all) return;
    if (e.bitmap) { e.bitmap.close(); e.bitmap = null; }
    if (all) e.blob = null;
  };
  P.put = (token, f, b64, scale) => {
    if (token !== P.token) return;
    let bytes;
    if (Uint8Array.fromBase64) bytes = Uint8Array.fromBase64(b64);  // native: 20× faster than the loop
    else {
      const bin = atob(b64);
      bytes = new Uint8Array(bin.length);
      for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    }
    const e = P.entry(f);
    e.blob = new Blob([bytes], {type: "image/jpeg"}); e.blobScale = scale || 1;
    P.requested.delete(f);
    if (e === P.current && e.bitmap && e.scale < e.blobScale && !e.loading) P.decode(e);  // sharper, for a zoom
    P.prepare();
    if (P.requested.size <= 4) P.report(false);  // the frames asked for are coming in: ask for the next ones
  };
  // a frame the page has, but with fewer pixels than the view needs now (a zoom): asked for again
  P.blurry = (e) => !!(e && e.blob && e.blobScale < P.scaleNeeded() - 1e-6);
  // frames wanted around the cursor, most wanted first: the cursor, then ahead in the direction, one behind, ...
  // while playing: the frames from a little ahead of the clock (those due now arrive late) to `ahead`, then
  // those due now, then those between the frame shown and the clock (late, but shown if they come first)
  // frames the clock moves on while a frame is decoded (at least 4): frames due sooner than that are late
  // (at most half the frames kept ahead: a page that cannot keep up still shows every few frames)
  const lead = () => Math.min(Math.floor(P.cfg.ahead / 2),
    Math.max(4, Math.ceil((P.decodeMs || 100) * Math.min(P.cfg.fps * P.speed, 60) / 1000)));
  P.window = () => {
    const c = P.cfg, d = P.dir >= 0 ? 1 : -1, g = P.goal;
    let out = [];
    if (P.playing) {
      const L = Math.min(lead(), c.ahead);
      for (let k = L; k <= c.ahead; k++) out.push(g + d * k);
      for (let k = 0; k < L; k++) out.push(g + d * k);
      for (let f = g - d; (f - P.shown) * d > 0; f -= d) out.push(f);
      if (c.loop && d > 0) out = out.map((f) => (f > c.hi ? c.lo + (f - c.hi - 1) % (c.hi - c.lo + 1) : f));
    } else {
      out.push(g);
      for (let k = 1; k <= Math.max(c.ahead, c.behind); k++) {
        if (k <= c.ahead) out.push(g + d * k);
        if (k <= c.behind) out.push(g - d * k);
        if (k === 2) out.push(g + 10 * d, g - 10 * d);  // where Shift+L / Shift+J go
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
      if (e.bitmap && (!keep.has(e.f) || (e.scale < Math.min(need, e.blobScale || 1) && !e.loading))) P.drop(e, false);
    }
    if (P.entries.size > P.cfg.max_blobs) {
      const far = Array.from(P.entries.values()).sort((a, b) => Math.abs(b.f - P.goal) - Math.abs(a.f - P.goal));
      for (const e of far.slice(0, P.entries.size - P.cfg.max_blobs)) {
        if (e === P.current) continue;
        P.drop(e, true); P.entries.delete(e.f);
      }
    }
    // playing: decode the frames in the order they fall due, from those the clock will reach once decoded
    let soonest = order;
    if (P.playing) {
      const has = (f) => { const e = P.entries.get(f); return !!(e && e.blob); };
      const ahead = Array.from(keep).filter((f) => (f - P.goal) * P.dir >= 0 && has(f)).sort((a, b) => (a - b) * P.dir);
      const due = ahead.filter((f) => (f - P.goal) * P.dir >= 0.7 * lead());
      soonest = due.length ? due : ahead;
      if (!soonest.length) {  // nothing ahead of the clock has come: the newest frame past the one shown, late
        const late = Array.from(keep).filter((f) => (f - P.shown) * P.dir > 0 && (P.goal - f) * P.dir >= 0 && has(f));
        late.sort((a, b) => (b - a) * P.dir);
        soonest = late.slice(0, 1);  // (but newer than the one shown: dropping frames, not lagging further)
      }
    }
    for (const f of soonest) {
      if (P.decoding >= 4) break;
      if (!keep.has(f)) break;
      const e = P.entries.get(f);
      if (!e || !e.blob || e.loading || e.bitmap) continue;
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
    const token = P.token, blobScale = e.blobScale || 1, scale = Math.min(P.scaleNeeded(), blobScale);
    const opts = {};
    if (scale < blobScale - 1e-6) {  // the server sent more pixels than the view needs now
      opts.resizeWidth = Math.max(16, Math.round(P.cfg.width * scale));
      opts.resizeHeight = Math.max(16, Math.round(P.cfg.height * scale));
      opts.resizeQuality = "low";
    }
    const t0 = now();
    createImageBitmap(e.blob, opts).then((bm) => {
      e.loading = false; P.decoding -= 1;
      P.decodeMs = 0.8 * (P.decodeMs || 100) + 0.2 * (now() - t0);  // running mean of the decode latency
      if (token !== P.token || !P.entries.has(e.f)) { bm.close(); return; }
      const sharper = !!e.bitmap;  // a zoom asked for more pixels: replace the picture
      if (e.bitmap) e.bitmap.close();
      e.bitmap = bm; e.scale = scale; P.lastScale = scale;
      if (sharper && P.current === e) P.draw(e);
      else if (e.f === P.goal && P.drawn !== e.f && !P.playing) P.show(e.f);
      P.prepare();
    }, (err) => { e.loading = false; P.decoding -= 1; if (!e.bitmap) e.blob = null; P.failed = String(err); P.prepare(); });
  };
  P.sharpen = () => {  // the frame shown, with the pixels a zoom needs: decoded again, or asked for again
    const e = P.current;
    if (!e || !e.blob || e.loading || e.scale === undefined || e.scale >= P.scaleNeeded()) return;
    if (P.blurry(e)) P.report(false); else P.decode(e);
  };

  // ------------------------------------------------------------------------------------ the cursor
  P.draw = (e) => {
    if (P.cfg.kind !== "plane") { P.drawReview(e); P.drawn = e.f; return; }
    const c = P.frameCanvas, bm = e.bitmap;
    if (c.width !== bm.width || c.height !== bm.height) { c.width = bm.width; c.height = bm.height; }
    P.ctx.drawImage(bm, 0, 0);
    const first = P.drawn === undefined;
    P.drawn = e.f;
    if (first || c.style.visibility === "hidden") P.place();
    else if (c.width * c.height && c.dataset.size !== c.width + "x" + c.height) P.place();
    c.dataset.size = c.width + "x" + c.height;
  };
  P.clamp = (f) => Math.max(P.cfg.lo, Math.min(P.cfg.hi, Math.round(f)));
  P.show = (f) => {
    const e = P.entries.get(f);
    if (!e || !P.ready(f)) return false;
    P.current = e; P.shown = f;
    P.draw(e);
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
    P.requested.clear();  // the server drops the frames a playing clock passes: ask again for those still wanted
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
    for (const [f, at] of P.requested) {  // asked for long ago, or passed by the clock (the server drops those)
      if (t - at > 3000 || (P.playing && (f - P.goal) * P.dir < 0)) P.requested.delete(f); else inflight += 1;
    }
    const win = P.window();
    for (const f of win) {
      // at most a few frames on their way; the frame to show when not playing is always asked for
      if (inflight + want.length >= (P.playing ? 2 * P.cfg.ahead : 8) && (P.playing || f !== win[0])) break;
      const e = P.entries.get(f);
      if ((e && e.blob && !P.blurry(e)) || P.requested.has(f)) continue;
      want.push(f); P.requested.set(f, t);
    }
    const m = P.viewer();
    if (!m) return;
    P.seq += 1;
    const msg = {seq: P.seq, token: P.token, shown: P.shown, goal: P.goal, dir: P.dir,
                 playing: !!P.playing, cmd: P.cmd || 0, scale: P.scaleNeeded(), want: want};
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


def put_frame_js(token: str, frame: int, jpeg: bytes, scale: float = 1.0) -> str:
    """The page call that hands it one compressed frame (``scale``: its share of the full size)."""
    return (f"window.__r3dPlayer && window.__r3dPlayer.put({json.dumps(token)}, {int(frame)}, "
            f"\"{base64.b64encode(jpeg).decode('ascii')}\", {float(scale)!r});")


PROBE_JS = r"""
(pts) => {
  // grey levels of the picture on screen at CSS pixels `pts` of viser's canvas: from the page player's frame
  // canvas where it shows the frame (mapped through its on-screen box), else from viser's WebGL drawing buffer
  const gl = document.querySelector('canvas[data-engine^="three.js"]');
  const own = gl.parentElement.querySelector("canvas.r3d-frame");
  const g = gl.getBoundingClientRect();
  if (own && own.style.visibility === "visible") {
    const r = own.getBoundingClientRect(), ctx = own.getContext("2d");
    return pts.map(([x, y]) => {
      const u = Math.floor((x + g.left - r.left) / r.width * own.width);
      const v = Math.floor((y + g.top - r.top) / r.height * own.height);
      const d = ctx.getImageData(Math.max(0, Math.min(own.width - 1, u)), Math.max(0, Math.min(own.height - 1, v)), 1, 1).data;
      return (d[0] + d[1] + d[2]) / 3;
    });
  }
  const c = gl.getContext("webgl2") || gl.getContext("webgl"), one = new Uint8Array(4);
  const s = c.drawingBufferWidth / gl.clientWidth, H = c.drawingBufferHeight;
  return pts.map(([x, y]) => {
    c.readPixels(Math.round(x * s), H - 1 - Math.round(y * s), 1, 1, c.RGBA, c.UNSIGNED_BYTE, one);
    return (one[0] + one[1] + one[2]) / 3;
  });
}
"""
"""For tests and benchmarks: ``page.evaluate(PROBE_JS, points)`` reads the picture on screen (the frame's own
canvas, or viser's WebGL buffer before the page's player draws) at CSS pixels of viser's canvas."""
