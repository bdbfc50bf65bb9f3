"""See a robot's motion with its meshes: one self-contained, animated HTML page.

:func:`write_mesh_replay` takes a robot (:class:`~robots.models.RobotModel`, or what
:func:`~robots.models.load` takes: a name or a URDF path) and one or several ``q``
trajectories — arrays, or :class:`~robots.simulate.SimulationResult` runs — and writes
one HTML file that opens from disk with no server and no network: meshcat's viewer
(three.js, WebGL; its script is copied into the page) with the robot's visual meshes,
every run selectable, with play/pause, a time slider and meshcat's mouse camera. The
address ``page.html#run=LABEL&t=1.5`` opens run ``LABEL`` paused at 1.5 s.

The meshes are the URDF's ``<visual>`` geometry as pinocchio loads it (through coal:
STL, DAE, OBJ and primitives, ``meshScale`` applied; ``package://`` paths resolve
against the robot's ``package_dirs``, else the folders above its URDF), decimated by
quadric edge collapse (``fast-simplification``) to a triangle budget for the whole
robot, so that a page stays a few megabytes. Each body is drawn at the placement of its frame in the
robot's own model, so a robot with locked joints (``from_urdf(..., locked_joints=)``)
shows those bodies where they were locked, and frames added with
:meth:`~robots.models.RobotModel.with_point_frame` (a sword tip) are drawn as a thin
rod from their parent frame. Poses are sampled at ``fps`` frames per second and
stored as 32-bit floats; the viewer interpolates between them.

Needs the ``view`` extra (meshcat and fast-simplification).
"""

from __future__ import annotations

import base64
import functools
import html as html_lib
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from prioik.errors import PrioikError

from .models import RobotModel, StateError, has_free_flyer_joint, load

__all__ = ["FPS", "TRIANGLES", "MeshReplayError", "write_mesh_replay"]

#: frames per second the poses are sampled at (the viewer interpolates between them)
FPS = 25
#: triangles of the whole robot's meshes after decimation (default budget)
TRIANGLES = 40_000
#: the smallest number of triangles a mesh is decimated to
MIN_TRIANGLES_PER_MESH = 60
#: radius (m) of the rod drawn for a point frame (a sword, a tool tip)
ROD_RADIUS = 0.008
#: the colours the markers are drawn with, in turn
MARKER_RGB = (0xd62728, 0x2ca02c, 0x9467bd, 0x8c564b)


class MeshReplayError(PrioikError, ValueError):
    """The robot's meshes cannot be read, or the trajectories given are malformed."""


@dataclass
class _Run:
    label: str
    t: np.ndarray            # k times (s)
    q: np.ndarray            # k × n_q
    note: str = ""           # shown at the last frame (why a run stopped)


@dataclass
class _Part:
    frame: str               # frame of the robot's model the part moves with
    name: str
    local: np.ndarray        # 4 × 4, the part in its frame (scale included)
    geometry: object         # a meshcat geometry
    rgba: tuple
    triangles: int


# ---------------------------------------------------------------------- the meshes
def _urdf_of(robot: RobotModel) -> Path:
    source = Path(robot.source)
    if not source.is_file():
        raise MeshReplayError(f"robot {robot.name!r} has no URDF to read its meshes from "
                              f"(source: {robot.source!r}); load it with "
                              "prioik.robots.from_urdf")
    return source


def _visual_model(source: Path, package_dirs: tuple[str, ...], floating: bool
                  ) -> tuple[pin.Model, pin.GeometryModel]:
    """The URDF's kinematic tree (as pinocchio builds it, before any locking) and its
    visual geometry model."""
    import xml.etree.ElementTree as ET
    try:
        if floating and not has_free_flyer_joint(ET.parse(source).getroot()):
            model = pin.buildModelFromUrdf(str(source), pin.JointModelFreeFlyer(),
                                           "root_joint")
        else:
            model = pin.buildModelFromUrdf(str(source))
    except (RuntimeError, ValueError, ET.ParseError) as exc:
        raise MeshReplayError(f"pinocchio could not build a model from {source}: "
                              f"{exc}") from None
    # package://NAME/... resolves against a folder holding NAME: the robot's package
    # dirs, else the folders above the URDF (a description package laid out as usual)
    dirs = list(package_dirs) or [str(d) for d in source.resolve().parents]
    try:
        visual = pin.buildGeomFromUrdf(model, str(source), pin.GeometryType.VISUAL,
                                        package_dirs=dirs)
    except (RuntimeError, ValueError, OSError) as exc:
        raise MeshReplayError(f"pinocchio could not load the visual meshes of {source} "
                              f"(package dirs {dirs}): {exc}") from None
    return model, visual


def _triangles_of(geometry) -> tuple[np.ndarray, np.ndarray] | None:
    """Vertices (scaled) and triangles of a coal mesh, ``None`` for a primitive."""
    if not (hasattr(geometry, "num_tris") and hasattr(geometry, "vertices")):
        return None
    n = int(geometry.num_tris)
    faces = np.array([(t[0], t[1], t[2]) for t in map(geometry.tri_indices, range(n))],
                     dtype=np.int64).reshape(n, 3)
    return np.array(geometry.vertices(), dtype=float).reshape(-1, 3), faces


def _decimate(vertices: np.ndarray, faces: np.ndarray, target: int):
    """``(vertices, faces)`` with about ``target`` triangles (quadric edge collapse)."""
    if len(faces) <= target:
        return vertices, faces
    import fast_simplification
    v, f = fast_simplification.simplify(vertices, faces, target_count=int(target))
    if len(f) == 0:                       # a mesh that collapses entirely stays whole
        return vertices, faces
    return np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)


def robot_parts(robot: RobotModel, triangles: int = TRIANGLES) -> list[_Part]:
    """The robot's visual parts, each in the frame of ``robot.model`` it moves with,
    meshes decimated so that the whole robot has about ``triangles`` triangles."""
    source = _urdf_of(robot)
    urdf_model, parts = _urdf_parts(str(source), source.stat().st_mtime_ns,
                                    tuple(robot.package_dirs), bool(robot.floating_base),
                                    int(triangles))
    for p in parts:
        if not robot.model.existFrame(p.frame):
            raise MeshReplayError(f"robot {robot.name!r}: the visual {p.name!r} hangs on "
                                  f"frame {p.frame!r}, which its model does not have")
    return [*parts, *_point_frame_rods(robot, urdf_model)]


@functools.lru_cache(maxsize=8)
def _urdf_parts(source: str, mtime_ns: int, package_dirs: tuple[str, ...], floating: bool,
                triangles: int) -> tuple[pin.Model, tuple[_Part, ...]]:
    """The URDF's visual parts in the frames of its own model (read-only, cached: a
    page per scenario variant decimates once)."""
    import meshcat.geometry as mg
    from pinocchio.visualize.meshcat_visualizer import loadPrimitive

    urdf_model, visual = _visual_model(Path(source), package_dirs, floating)
    meshes, parts = [], []
    for g in visual.geometryObjects:
        frame = urdf_model.frames[g.parentFrame]
        # the part in its body frame: both placements are in the same parent joint
        local = (frame.placement.inverse() * g.placement).homogeneous
        rgba = tuple(float(c) for c in np.clip(g.meshColor, 0.0, 1.0))
        mesh = _triangles_of(g.geometry)
        if mesh is None:
            obj = loadPrimitive(g)
            if obj is None:
                raise MeshReplayError(f"{Path(source).name}: visual {g.name!r} is a "
                                      f"{type(g.geometry).__name__}, which cannot be drawn")
            local = local @ np.diag([*np.asarray(g.meshScale, float), 1.0])
            parts.append(_Part(frame.name, g.name, local, obj, rgba, 0))
        else:
            meshes.append((frame.name, g, local, rgba, *mesh))
    total = sum(len(f) for *_, f in meshes)
    share = min(1.0, triangles / total) if total else 1.0
    for name, g, local, rgba, v, f in meshes:
        if len(f) == 0:
            continue
        v, f = _decimate(v, f, max(MIN_TRIANGLES_PER_MESH, int(round(share * len(f)))))
        if np.prod(np.sign(g.meshScale)) < 0:   # a mirrored mesh: keep faces outward
            f = f[:, ::-1]
        parts.append(_Part(name, g.name, local, mg.TriangularMeshGeometry(v, f), rgba,
                           len(f)))
    return urdf_model, tuple(parts)


def _point_frame_rods(robot: RobotModel, urdf_model: pin.Model) -> list[_Part]:
    """A thin rod from the parent frame to each frame the URDF does not have."""
    import meshcat.geometry as mg
    rods = []
    for frame in robot.model.frames:
        if urdf_model.existFrame(frame.name) or frame.name == "universe":
            continue
        parent = robot.model.frames[frame.parentFrame]
        # the parent's origin seen from the frame (both fixed in the same joint)
        offset = (frame.placement.inverse() * parent.placement).translation
        length = float(np.linalg.norm(offset))
        if length < 1e-6:
            continue
        # meshcat's cylinder runs along y: rotate y onto the rod, centre it halfway
        axis = offset / length
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 1.0, 0.0]), axis)
        local = np.eye(4)
        local[:3, :3] = rotation.toRotationMatrix()
        local[:3, 3] = 0.5 * offset
        rods.append(_Part(frame.name, frame.name + "_rod", local,
                          mg.Cylinder(length, ROD_RADIUS), (0.55, 0.57, 0.6, 1.0), 0))
    return rods


# ----------------------------------------------------------------- trajectories
def _runs(robot: RobotModel, runs, dt: float | None, labels) -> list[_Run]:
    """The trajectories given, as ``_Run``s (validated, copied)."""
    from .simulate import SimulationResult
    several = isinstance(runs, Mapping) or (
        isinstance(runs, Sequence) and len(runs) > 0 and
        (isinstance(runs[0], SimulationResult) or np.ndim(runs[0]) == 2))
    if not several:
        runs = [runs]                                   # one trajectory
    if isinstance(runs, Mapping):
        items = list(runs.items())
        if labels is not None:
            raise MeshReplayError("labels name the runs of a sequence; a mapping's keys "
                                  "already name them")
    else:
        runs = list(runs)
        if labels is None:
            labels = ["run"] if len(runs) == 1 else [f"run {i + 1}" for i in range(len(runs))]
        labels = [str(x) for x in labels]
        if len(labels) != len(runs):
            raise MeshReplayError(f"{len(labels)} labels for {len(runs)} runs")
        items = list(zip(labels, runs, strict=False))
    if not items:
        raise MeshReplayError("no trajectory to replay")
    if len({label for label, _ in items}) != len(items):
        raise MeshReplayError("two runs have the same label")
    out = []
    for label, run in items:
        if isinstance(run, SimulationResult):
            q, t = np.array(run.q, dtype=float), np.array(run.t, dtype=float)
            note = f"stopped: {run.message}" if run.failed else ""
        else:
            try:
                q = np.array(run, dtype=float)
            except (TypeError, ValueError) as exc:
                raise MeshReplayError(f"run {label!r}: q cannot be read as numbers "
                                      f"({exc})") from None
            if dt is None or not (math.isfinite(dt) and dt > 0):
                raise MeshReplayError(f"dt must be a positive time step (s), got {dt!r}")
            t = dt * np.arange(len(q)) if q.ndim == 2 else np.zeros(0)
            note = ""
        out.append(_Run(str(label), t, _checked_q(robot, q, str(label)), note))
    return out


def _checked_q(robot: RobotModel, q: np.ndarray, label: str) -> np.ndarray:
    if q.ndim != 2 or q.shape[1] != robot.nq or len(q) == 0:
        raise StateError(f"run {label!r}: q must be a k × {robot.nq} array (k ≥ 1) for "
                         f"robot {robot.name!r}, got shape {q.shape}")
    bad = np.argwhere(~np.isfinite(q))
    if len(bad):
        raise StateError(f"run {label!r}: q[{bad[0][0]}, {bad[0][1]}] is {q[tuple(bad[0])]}")
    for lo, size, joint in robot.unit_norm_parts():
        norms = np.linalg.norm(q[:, lo:lo + size], axis=1)
        off = np.flatnonzero(np.abs(norms - 1.0) > 1e-6)
        if len(off):
            raise StateError(f"run {label!r}: q[{off[0]}, {lo}:{lo + size}] (joint "
                             f"{joint!r}) has norm {norms[off[0]]:.6g}; it must be 1")
    return q


def _sample(t: np.ndarray, fps: int) -> list[int]:
    """Indices of the rows shown: one per ``1/fps`` s, the last row included."""
    if len(t) == 1:
        return [0]
    step = float(np.median(np.diff(t)))
    every = max(1, int(round(1.0 / (fps * step)))) if step > 0 else 1
    idx = list(range(0, len(t), every))
    if idx[-1] != len(t) - 1:
        idx.append(len(t) - 1)
    return idx


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype="<f4").tobytes()).decode()


def _run_payload(robot: RobotModel, run: _Run, frames: list[str], markers, fps: int
                 ) -> dict:
    model, data = robot.model, robot.data()
    ids = [model.getFrameId(f) for f in frames]
    idx = _sample(run.t, fps)
    poses = np.empty((len(idx), len(ids), 7))
    points, names = [], None
    for row, k in enumerate(idx):
        pin.framesForwardKinematics(model, data, run.q[k])
        for col, fid in enumerate(ids):
            M = data.oMf[fid]
            poses[row, col, :3] = M.translation
            poses[row, col, 3:] = pin.Quaternion(M.rotation).coeffs()   # x, y, z, w
        if markers is not None:
            names, xyz = _marker_points(markers, float(run.t[k]), names)
            points.append(xyz)
    # per frame node: positions (k × 3) then quaternions (k × 4)
    per_frame = [np.concatenate([poses[:, c, :3].ravel(), poses[:, c, 3:].ravel()])
                 for c in range(len(ids))]
    out = {"t": _b64(run.t[idx] - run.t[idx[0]]), "frames": _b64(np.concatenate(per_frame)),
           "note": run.note, "marker_names": names or [],
           "markers": _b64(np.transpose(np.array(points), (1, 0, 2))) if points else ""}
    return out


def _marker_points(markers, t: float, names: list[str] | None
                   ) -> tuple[list[str], list[np.ndarray]]:
    """The marker names and positions at ``t`` (the names those of the first call)."""
    mk = markers(t)
    if not isinstance(mk, Mapping) or (names is not None and list(mk) != names):
        raise MeshReplayError(f"markers({t:g}) must give the same names → xyz mapping at "
                              f"every time, got {mk!r:.120}")
    out = []
    for name, value in mk.items():
        try:
            xyz = np.asarray(value, dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise MeshReplayError(f"marker {name!r} at t = {t:g} is not 3 numbers: "
                                  f"{value!r:.80}") from None
        if not np.isfinite(xyz).all():
            raise MeshReplayError(f"marker {name!r} at t = {t:g} is not finite: {xyz}")
        out.append(xyz)
    return list(mk), out


# -------------------------------------------------------------------- the page
class _Recorder:
    """A meshcat window that keeps the commands (msgpack) instead of sending them."""

    def __init__(self) -> None:
        self.commands: list[bytes] = []

    def send(self, command) -> None:
        import umsgpack
        self.commands.append(umsgpack.packb(command.lower()))


def _node(name: str) -> str:
    return name.replace("/", "_")


def _meshcat_script() -> str:
    import meshcat
    path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    if not path.is_file():
        raise MeshReplayError(f"meshcat's viewer script is missing ({path})")
    return path.read_text(encoding="utf-8")


def write_mesh_replay(path: str | os.PathLike, robot: RobotModel | str | os.PathLike,
                      runs, *, dt: float | None = None, labels: Sequence[str] | None = None,
                      title: str | None = None,
                      markers: Callable[[float], Mapping[str, np.ndarray]] | None = None,
                      fps: int = FPS, triangles: int = TRIANGLES) -> Path:
    """Write a self-contained HTML page animating ``robot`` with its meshes.

    Args:
        path: The ``.html`` file to write (its folder is created).
        robot: A :class:`~robots.models.RobotModel` loaded from a URDF, or a name or
            URDF path for :func:`~robots.models.load`.
        runs: One trajectory — a ``k × n_q`` array (or sequence of ``q``) or a
            :class:`~robots.simulate.SimulationResult` — or several: a sequence of them
            (named by ``labels``) or a mapping label → trajectory. Each run is one
            entry of the page's run selector.
        dt: Time between two rows of an array trajectory (s); required for arrays
            (a ``SimulationResult`` carries its times).
        labels: Names of the runs of a sequence (default ``run 1``, ``run 2``, ...).
        title: The page's title (default: the robot's name).
        markers: ``t ↦ {name: xyz}``, points drawn as spheres (targets, references).
        fps: Poses per second stored (the viewer interpolates between them).
        triangles: Triangle budget of the whole robot's meshes (decimated to it).

    Returns:
        The path written.

    Raises:
        MeshReplayError: no URDF or unreadable meshes, malformed runs or labels.
        StateError: a ``q`` of the wrong size, not finite, or with a non-unit
            quaternion (names the run and the row).
        MissingExtraError: meshcat or fast-simplification is not installed.
    """
    from prioik.extras import require
    require("view", what="write_mesh_replay")
    if not isinstance(robot, RobotModel):
        robot = load(robot)
    if not (isinstance(fps, (int, np.integer)) and fps > 0):
        raise MeshReplayError(f"fps must be a positive integer, got {fps!r}")
    if not (isinstance(triangles, (int, np.integer)) and triangles > 0):
        raise MeshReplayError(f"triangles must be a positive integer, got {triangles!r}")
    _urdf_of(robot)
    trajectories = _runs(robot, runs, dt, labels)
    parts = robot_parts(robot, int(triangles))

    import meshcat
    from meshcat.geometry import MeshPhongMaterial
    recorder = _Recorder()
    viewer = meshcat.Visualizer(window=recorder)
    frames = list(dict.fromkeys(p.frame for p in parts))
    for p in parts:
        material = MeshPhongMaterial(color=int(round(p.rgba[0] * 255)) * 65536 +
                                     int(round(p.rgba[1] * 255)) * 256 +
                                     int(round(p.rgba[2] * 255)),
                                     opacity=p.rgba[3])
        node = viewer["robot"][_node(p.frame)][_node(p.name)]
        node.set_object(p.geometry, material)
        node.set_transform(p.local)
    meshes = [base64.b64encode(c).decode() for c in recorder.commands]
    payload = {
        "title": title or robot.name,
        "frames": [_node(f) for f in frames],
        "triangles": int(sum(p.triangles for p in parts)),
        "marker_rgb": list(MARKER_RGB),
        "runs": {r.label: _run_payload(robot, r, frames, markers, int(fps))
                 for r in trajectories},
    }
    text = (_PAGE.replace("__TITLE__", html_lib.escape(payload["title"]))
            .replace("__MESHCAT__", _meshcat_script().replace("</script", "<\\/script"))
            .replace("__MESHES__", _json(meshes))
            .replace("__DATA__", _json(payload)))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def _json(value) -> str:
    """JSON safe inside a ``<script>`` element."""
    return json.dumps(value, separators=(",", ":")).replace("</", "<\\/")


# The page: meshcat's viewer, the robot's parts added by their meshcat commands (MESHES,
# one per line), then per run one animation clip per frame node built from DATA.
# window.prioikReplay.meshes counts the robot's drawn meshes (read by the browser test).
_PAGE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
body{margin:0;font:13px system-ui,sans-serif;overflow:hidden}
#meshcat-pane{width:100vw;height:100vh;overflow:hidden}
#bar{position:absolute;left:0;bottom:0;display:flex;gap:10px;align-items:center;
padding:6px 10px;background:rgba(255,255,255,.85);border-top-right-radius:6px}
#info{font-variant-numeric:tabular-nums} .note{color:#b00}
</style></head><body>
<div id="meshcat-pane"></div>
<div id="bar"><b>__TITLE__</b>
<label>run <select id="run"></select></label>
<button id="play">pause</button>
<input id="slider" type="range" min="0" max="1000" value="0" style="width:220px">
<span id="info"></span></div>
<script>
__MESHCAT__
</script>
<script>
const MESHES = __MESHES__;
const DATA = __DATA__;
const THREE = MeshCat.THREE;
const viewer = new MeshCat.Viewer(document.getElementById('meshcat-pane'));
function bytes(b64) {
  const s = atob(b64), out = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
  return out;
}
const floats = b64 => b64 ? new Float32Array(bytes(b64).buffer) : new Float32Array(0);
for (const m of MESHES) viewer.handle_command_bytearray(bytes(m));
viewer.set_property(['Axes'], 'visible', false);
const grid = new THREE.GridHelper(4, 16, 0x555555, 0x999999);   // 0.25 m squares
grid.rotateX(Math.PI / 2);
viewer.set_object(['Grid'], grid);
const sel = document.getElementById('run'), slider = document.getElementById('slider');
const info = document.getElementById('info'), playBtn = document.getElementById('play');
for (const label of Object.keys(DATA.runs)) {
  const o = document.createElement('option'); o.value = label;
  o.textContent = label + (DATA.runs[label].note ? ' (stopped)' : ''); sel.appendChild(o);
}
let run = null, times = null;
function markerNodes(names) {
  viewer.delete_path(['meshcat', 'markers']);
  names.forEach((n, i) => {
    const mesh = new THREE.Mesh(new THREE.SphereGeometry(i ? 0.015 : 0.03, 16, 12),
      new THREE.MeshPhongMaterial({color: DATA.marker_rgb[i % DATA.marker_rgb.length]}));
    viewer.set_object(['meshcat', 'markers', n], mesh);
  });
}
function pick(label) {
  run = DATA.runs[label]; times = floats(run.t);
  const k = times.length, all = floats(run.frames), animations = [];
  const pose = all.subarray(0, 7 * k);   // the first frame node, for the camera
  DATA.frames.forEach((f, c) => {
    const block = all.subarray(7 * k * c, 7 * k * (c + 1));
    animations.push({path: ['meshcat', 'robot', f], clip: {name: 'default', fps: 1, tracks: [
      {name: '.position', type: 'vector3', times: times, values: block.subarray(0, 3 * k)},
      {name: '.quaternion', type: 'quaternion', times: times, values: block.subarray(3 * k)}]}});
  });
  markerNodes(run.marker_names);
  const pts = floats(run.markers), m = run.marker_names.length;
  run.marker_names.forEach((n, i) => {
    const v = pts.subarray(3 * k * i, 3 * k * (i + 1));
    animations.push({path: ['meshcat', 'markers', n], clip: {name: 'default', fps: 1, tracks: [
      {name: '.position', type: 'vector3', times: times, values: v}]}});
  });
  // played, then paused if asked: an action that never played does not pose its node
  viewer.set_animation(animations, {play: true, loopMode: THREE.LoopRepeat,
                                    repetitions: Infinity, clampWhenFinished: true});
  if (!playing) viewer.animator.pause();
  aim(all, k);
}
function aim(all, k) {
  // look at the middle of the frame origins at the first pose, from the front-right
  const lo = [1e9, 1e9, 1e9], hi = [-1e9, -1e9, -1e9];
  DATA.frames.forEach((f, c) => {
    for (let i = 0; i < 3; i++) {
      const x = all[7 * k * c + i];
      lo[i] = Math.min(lo[i], x); hi[i] = Math.max(hi[i], x);
    }
  });
  const c = lo.map((v, i) => 0.5 * (v + hi[i]));
  const size = Math.max(0.6, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
  const d = 1.2 * size, eye = [c[0] + 0.8 * d, c[1] - 0.55 * d, c[2] + 0.35 * d];
  // the camera hangs under a node turned +90° about x: world (x, y, z) is (x, z, -y) there
  viewer.controls.target.set(c[0], c[2], -c[1]);
  viewer.camera.position.set(eye[0], eye[2], -eye[1]);
  viewer.controls.update();
  viewer.set_transform(['Grid'], new THREE.Matrix4().makeTranslation(
    0.25 * Math.round(4 * c[0]), 0.25 * Math.round(4 * c[1]), 0).toArray());
  viewer.set_dirty();
}
let playing = true;
function clock() { return viewer.animator.actions.length ? viewer.animator.actions[0].time : 0; }
function show() {
  const d = times[times.length - 1] || 0, now = clock();
  if (document.activeElement !== slider) slider.value = d ? Math.round(1000 * now / d) : 0;
  const end = run.note && now >= d - 1e-6;
  info.textContent = 't = ' + now.toFixed(2) + ' s';
  if (end) {
    const note = document.createElement('span');
    note.className = 'note'; note.textContent = ' — ' + run.note; info.appendChild(note);
  }
  requestAnimationFrame(show);
}
sel.onchange = () => pick(sel.value);
playBtn.onclick = () => {
  playing = !playing; playBtn.textContent = playing ? 'pause' : 'play';
  playing ? viewer.animator.play() : viewer.animator.pause();
};
slider.oninput = () => {
  viewer.animator.seek(slider.value / 1000 * (times[times.length - 1] || 0));
};
// #run=LABEL&t=SECONDS in the address opens that run paused at that time
const want = new URLSearchParams(location.hash.slice(1));
if (want.has('run') && want.get('run') in DATA.runs) sel.value = want.get('run');
if (want.has('t')) { playing = false; playBtn.textContent = 'play'; }
pick(sel.value);
if (want.has('t')) viewer.animator.seek(Math.max(0, parseFloat(want.get('t')) || 0));
let count = 0;
viewer.scene_tree.find(['meshcat', 'robot']).object.traverse(o => {
  if (o.isMesh && o.geometry && o.geometry.attributes.position &&
      o.geometry.attributes.position.count > 0) count++;
});
window.prioikReplay = {meshes: count, triangles: DATA.triangles,
                       runs: Object.keys(DATA.runs).length};
document.body.dataset.meshes = count;
requestAnimationFrame(show);
</script></body></html>
"""
