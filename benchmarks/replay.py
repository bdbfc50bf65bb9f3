"""See the motion: a self-contained HTML replay of scenario runs, and a live meshcat view.

:func:`write_replay` writes one HTML file that opens from disk without a server or a
network: the robot as link geometry (segments between joint origins and to its named
frames), the scenario's markers (targets, the reference) and the trace of its tip frame
(the sword tip, the tool), animated over time, with a run selector (every run of a
variant in one page), play/pause, a time slider and a mouse-orbit camera. It draws on
a 2-D canvas (no WebGL, no external script), so it renders in any browser, headless
ones included. Positions are computed here with pinocchio (forward kinematics of the
saved ``q``), sampled at :data:`FPS` frames per second and stored in millimetres.

:func:`live_view` plays a run in meshcat (installed with PlaCo) through pinocchio's
``MeshcatVisualizer`` with the robot's meshes, for interactive use.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin

FPS = 50
#: the colour the page draws the robot's links with (the browser test looks for it)
ROBOT_RGB = (31, 78, 156)


def _scenario_of(res):
    from prioik.robots.scenarios import make
    info = res.info or {}
    if "scenario" not in info:
        raise ValueError("this run does not say which scenario it comes from "
                         "(SimulationResult.info['scenario']); replay needs the robot")
    sc = make(info["scenario"], info.get("variant"))
    return sc


def _skeleton(robot, tip_frame: str):
    """Joint indices drawn, segments between them, extra frame points."""
    m = robot.model
    # a fixed base is drawn from the world origin (the universe joint) up
    joints = list(range(1 if robot.floating_base else 0, m.njoints))
    index = {j: i for i, j in enumerate(joints)}
    segments = [(index[m.parents[j]], index[j]) for j in joints
                if j > 0 and m.parents[j] in index]
    frames = list(dict.fromkeys([*robot.frames.values(), tip_frame]))
    frame_ids = [robot.frame_id(f) for f in frames if robot.model.existFrame(f)]
    for k, fid in enumerate(frame_ids):
        parent = m.frames[fid].parentJoint
        if parent in index:
            segments.append((index[parent], len(joints) + k))
    return joints, frame_ids, segments


def replay_data(results: dict, fps: int = FPS) -> dict:
    """The page's data: per run, point positions (mm) per frame, segments, markers."""
    runs = {}
    scen = None
    for label, res in results.items():
        sc = _scenario_of(res) if scen is None or res.info.get("variant") != scen.variant \
            else scen
        scen = sc
        robot = sc.robot
        model, data = robot.model, robot.data()
        joints, frame_ids, segments = _skeleton(robot, sc.tip_frame)
        tip = robot.frame_id(sc.tip_frame)
        if res.steps == 0:
            continue
        dt = float(res.t[1] - res.t[0]) if res.steps > 1 else 1.0 / fps
        every = max(1, int(round(1.0 / (fps * dt))))
        idx = list(range(0, res.steps, every))
        if idx[-1] != res.steps - 1:
            idx.append(res.steps - 1)
        pts, tips, marks = [], [], []
        names = None
        for k in idx:
            pin.framesForwardKinematics(model, data, res.q[k])
            p = [data.oMi[j].translation for j in joints] + \
                [data.oMf[f].translation for f in frame_ids]
            pts.append(np.round(1e3 * np.array(p)).astype(int).ravel().tolist())
            tips.append(np.round(1e3 * data.oMf[tip].translation).astype(int).tolist())
            mk = sc.markers(float(res.t[k]))
            names = list(mk)
            marks.append([np.round(1e3 * np.asarray(v)).astype(int).tolist() for v in mk.values()])
        runs[label] = {"t": [round(float(res.t[k]), 4) for k in idx], "points": pts,
                       "segments": segments, "tip": tips, "markers": marks,
                       "marker_names": names, "failed": bool(res.failed),
                       "message": res.message, "joints": len(joints)}
    return {"runs": runs, "robot_rgb": list(ROBOT_RGB)}


def write_replay(path, results: dict, title: str = "prioik replay", fps: int = FPS) -> Path:
    """Write the self-contained replay page of ``results`` (label → SimulationResult,
    each with ``info['scenario']``) to ``path``; returns the path."""
    path = Path(path)
    payload = json.dumps(replay_data(results, fps), separators=(",", ":"))
    html = _PAGE.replace("__TITLE__", title).replace("__DATA__", payload)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html, encoding="utf-8")
    return path


def live_view(res, *, open_browser: bool = False, speed: float = 1.0):  # pragma: no cover
    """Play a run in meshcat with the robot's meshes (``MeshcatVisualizer``).

    Starts (or connects to) a meshcat server and prints its URL; ``open_browser``
    opens it. Interactive use only: the tests cover the HTML replay.
    """
    import time

    from pinocchio.visualize import MeshcatVisualizer

    from prioik.robots.models import example_robot_data_dir
    sc = _scenario_of(res)
    robot = sc.robot
    share = str(example_robot_data_dir().parent.parent)
    root = pin.JointModelFreeFlyer() if robot.floating_base else None
    args = (robot.source, [share]) + ((root,) if root is not None else ())
    model, collision, visual = pin.buildModelsFromUrdf(*args)
    if model.nq != robot.nq:                      # locked joints (the Panda's fingers)
        keep = set(robot.model.names)
        locked = [j for j in range(1, model.njoints) if model.names[j] not in keep]
        q_ref = pin.neutral(model)
        model, (collision, visual) = pin.buildReducedModel(model, [collision, visual],
                                                           locked, q_ref)
    viz = MeshcatVisualizer(model, collision, visual)
    viz.initViewer(open=open_browser)
    viz.loadViewerModel()
    print(f"meshcat: {viz.viewer.url()}")
    dt = float(res.t[1] - res.t[0]) if res.steps > 1 else 0.01
    every = max(1, int(round(1.0 / (FPS * dt))))
    for k in range(0, res.steps, every):
        t0 = time.perf_counter()
        viz.display(res.q[k])
        time.sleep(max(0.0, every * dt / speed - (time.perf_counter() - t0)))
    return viz


_PAGE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
body{margin:0;font:13px system-ui,sans-serif;background:#f4f5f7;color:#222}
#bar{display:flex;gap:10px;align-items:center;padding:6px 10px;background:#fff;
border-bottom:1px solid #ddd;flex-wrap:wrap}
#view{display:block;width:100vw;height:calc(100vh - 44px);cursor:grab}
#info{font-variant-numeric:tabular-nums} .fail{color:#b00}
</style></head><body>
<div id="bar"><b>__TITLE__</b>
<label>run <select id="run"></select></label>
<button id="play">pause</button>
<input id="slider" type="range" min="0" max="0" value="0" style="width:260px">
<span id="info"></span>
<span style="color:#666">drag: orbit · wheel: zoom</span></div>
<canvas id="view"></canvas>
<script>
const DATA = __DATA__;
const cv = document.getElementById('view'), ctx = cv.getContext('2d');
const sel = document.getElementById('run'), slider = document.getElementById('slider');
const info = document.getElementById('info'), playBtn = document.getElementById('play');
const RGB = 'rgb(' + DATA.robot_rgb.join(',') + ')';
const MARK = ['#d62728', '#2ca02c', '#9467bd', '#8c564b'];
let run = null, frame = 0, playing = true, az = -0.6, el = 0.35, zoom = 1.0, last = null;
let centre = [0, 0, 0], radius = 1;
for (const label of Object.keys(DATA.runs)) {
  const o = document.createElement('option'); o.value = label;
  o.textContent = label + (DATA.runs[label].failed ? ' (failed)' : ''); sel.appendChild(o);
}
function pick(label) {
  run = DATA.runs[label]; frame = 0; slider.max = run.t.length - 1; slider.value = 0;
  const p = run.points[0], n = p.length / 3, lo = [1e9, 1e9, 1e9], hi = [-1e9, -1e9, -1e9];
  const grow = (x, y, z) => {
    [x, y, z].forEach((v, i) => { lo[i] = Math.min(lo[i], v); hi[i] = Math.max(hi[i], v); });
  };
  for (let i = 0; i < n; i++) grow(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
  for (const m of run.markers[0]) grow(m[0], m[1], m[2]);
  centre = lo.map((v, i) => 0.5 * (v + hi[i]));
  radius = Math.max(300, 0.6 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
}
function project(x, y, z) {
  x -= centre[0]; y -= centre[1]; z -= centre[2];
  const ca = Math.cos(az), sa = Math.sin(az), ce = Math.cos(el), se = Math.sin(el);
  const xr = ca * x - sa * y, yr = sa * x + ca * y;          // about z
  const depth = ce * yr + se * z, up = -se * yr + ce * z;     // tilt
  const s = Math.min(cv.width, cv.height) / (2.4 * radius) * zoom;
  const persp = 1 / (1 + depth / (8 * radius));
  return [cv.width / 2 + xr * s * persp, cv.height / 2 - up * s * persp, depth];
}
function draw() {
  const w = cv.clientWidth, h = cv.clientHeight;
  if (cv.width !== w || cv.height !== h) { cv.width = w; cv.height = h; }
  ctx.fillStyle = '#f4f5f7'; ctx.fillRect(0, 0, cv.width, cv.height);
  if (!run) return;
  // ground grid (z = 0), 0.25 m squares
  ctx.strokeStyle = '#d5d8dd'; ctx.lineWidth = 1;
  const g = 250, span = Math.ceil(radius / g + 2) * g;
  for (let v = -span; v <= span; v += g) {
    let a = project(centre[0] + v, centre[1] - span, 0);
    let b = project(centre[0] + v, centre[1] + span, 0);
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
    a = project(centre[0] - span, centre[1] + v, 0);
    b = project(centre[0] + span, centre[1] + v, 0);
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
  }
  const p = run.points[frame], n = p.length / 3, P = [];
  for (let i = 0; i < n; i++) P.push(project(p[3 * i], p[3 * i + 1], p[3 * i + 2]));
  // tip trace up to now
  ctx.strokeStyle = '#ff7f0e'; ctx.lineWidth = 2; ctx.beginPath();
  for (let k = 0; k <= frame; k++) {
    const q = project(...run.tip[k]); k ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]);
  }
  ctx.stroke();
  // links, far ones first
  const segs = run.segments.map(([a, b]) => [a, b, P[a][2] + P[b][2]]).sort((u, v) => v[2] - u[2]);
  ctx.lineCap = 'round'; ctx.strokeStyle = RGB; ctx.lineWidth = 7;
  for (const [a, b] of segs) {
    ctx.beginPath(); ctx.moveTo(P[a][0], P[a][1]); ctx.lineTo(P[b][0], P[b][1]); ctx.stroke();
  }
  ctx.fillStyle = '#0b2545';
  for (let i = 0; i < run.joints; i++) {
    ctx.beginPath(); ctx.arc(P[i][0], P[i][1], 3.5, 0, 7); ctx.fill();
  }
  // markers
  run.markers[frame].forEach((m, i) => {
    const q = project(...m); ctx.fillStyle = MARK[i % MARK.length];
    ctx.beginPath(); ctx.arc(q[0], q[1], i ? 4 : 7, 0, 7); ctx.fill();
    ctx.fillText(run.marker_names[i], q[0] + 9, q[1] - 6);
  });
  const tip = project(...run.tip[frame]);
  ctx.fillStyle = '#ff7f0e'; ctx.beginPath(); ctx.arc(tip[0], tip[1], 5, 0, 7); ctx.fill();
  const end = frame === run.t.length - 1 && run.failed;
  info.innerHTML = 't = ' + run.t[frame].toFixed(2) + ' s' +
    (end ? ' <span class="fail">— stopped: ' + run.message + '</span>' : '');
}
function tick(ts) {
  if (playing && run) {
    if (last === null) last = ts;
    const want = Math.floor((ts - last) / 1000 * 50);
    if (want > 0) { frame = (frame + want) % run.t.length; slider.value = frame; last = ts; }
  } else last = null;
  draw(); requestAnimationFrame(tick);
}
sel.onchange = () => { pick(sel.value); draw(); };
slider.oninput = () => { frame = +slider.value; draw(); };
playBtn.onclick = () => { playing = !playing; playBtn.textContent = playing ? 'pause' : 'play'; };
let drag = null;
cv.onmousedown = e => { drag = [e.clientX, e.clientY]; };
window.onmouseup = () => { drag = null; };
window.onmousemove = e => { if (!drag) return; az += (e.clientX - drag[0]) * 0.01;
  el = Math.max(-1.4, Math.min(1.4, el + (e.clientY - drag[1]) * 0.01));
  drag = [e.clientX, e.clientY]; draw(); };
cv.onwheel = e => { e.preventDefault(); zoom *= Math.exp(-e.deltaY * 0.001); draw(); };
pick(sel.value); draw(); requestAnimationFrame(tick);
</script></body></html>
"""
