# Run: OPENBLAS_NUM_THREADS=1 .venv/bin/python tests/bad_input_table.py OUT.json (not a test module: a measurement)
"""Bad-input table: each case is handled when the library answers right or raises its
own error (class defined in prioik) whose message names the culprit; CLI cases when the
exit status is right and stderr is one line naming the culprit."""
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
from types import SimpleNamespace

import numpy as np

rows = []


def own(exc, word):
    return type(exc).__module__.startswith("prioik") and word.lower() in str(exc).lower()


def api(group, name, fn, word=None, check=None):
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            out = fn()
    except Exception as exc:  # noqa: BLE001
        ok = word is not None and own(exc, word)
        rows.append((group, name, ok, f"{type(exc).__module__}.{type(exc).__name__}: {str(exc)[:90]}"))
        return
    ok = check(out) if check else False
    rows.append((group, name, ok, f"returned {str(out)[:90]}"))


import prioik.formulations as F
from prioik.hierarchy import Task, TaskStack, check_lexicographic


def S(A, b, **kw):
    return TaskStack([[Task("a", A, b, **kw)]])

# ---------------------------------------------------------------- API
api("API", "svd path on [[0]]", lambda: F.solve(S([[0.0]], [1.0]), "extended_jacobian", nullspace="svd").x,
    check=lambda x: np.allclose(x, 0))
for scale in (1e-200, 1e-160):
    for f, o in (("reference", {}), ("extended_jacobian", {}), ("extended_jacobian", {"kernel": "lapack"}),
                 ("extended_jacobian", {"nullspace": "svd"}), ("nullspace", {}),
                 ("hierarchical_active_set", {})):
        api("API", f"{scale:g}·I, {f} {o}", lambda: F.solve(S(scale * np.eye(2), [1.0, 2.0]), f, **o),
            word="scale", check=lambda s: s.status != "failed" and np.allclose(s.x * scale, [1, 2], rtol=1e-10)
            or s.status != "optimal")
api("API", "complex A (ndarray)", lambda: Task("a", np.array([[1 + 1j]]), [1.0]).A, "complex")
api("API", "complex A (list)", lambda: Task("a", [[1 + 1j]], [1.0]).A, "complex")
api("API", "string A", lambda: Task("a", [["1", "2"]], [1.0]).A, "string")
api("API", "boolean A", lambda: Task("a", [[True]], [1.0]).A, "boolean")
api("API", "string b", lambda: Task("a", [[1.0]], ["1"]).b, "b")
api("API", "complex b", lambda: Task("a", [[1.0]], [1j]).b, "b")
api("API", "string weight", lambda: Task("a", [[1.0]], [1.0], weight="2").weight, "weight")
api("API", "complex lower", lambda: Task("a", [[1.0]], lower=[1j]).lower, "lower")
st = S(np.eye(3), np.ones(3))
for x in (np.zeros(2), np.zeros((1, 3)), "abc"):
    api("API", f"check_lexicographic x={x!r}", lambda: check_lexicographic(st, x), "x")
small = S(np.eye(2), [1.0, 2.0])
for f, opts, word in (("extended_jacobian", {"damping": "a"}, "damping"),
                      ("extended_jacobian", {"damping": None}, "damping"),
                      ("extended_jacobian", {"level_damping": "x"}, "level_damping"),
                      ("extended_jacobian", {"rcond": "x"}, "rcond"),
                      ("extended_jacobian", {"rcond": -1}, "rcond"),
                      ("extended_jacobian", {"rcond": 2}, "rcond"),
                      ("nullspace", {"reproject": "no"}, "reproject"),
                      ("reference", {"metric": -np.eye(2)}, "metric"),
                      ("operational_space", {"mass_matrix": "a"}, "mass_matrix"),
                      ("cascaded_qp", {"backend_options": {"bogus": 1}}, "bogus")):
    api("API options (lead)", f"{f} {opts}", lambda: F.solve(small, f, **opts), word,
        check=lambda s: False)

# ---------------------------------------------------------------- robots
from prioik import robots as R
from prioik.robots import KinematicState, g1, joint_limit_violation, simulate, spatial_chain

robot = g1()
def state(change):
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    change(q, v)
    return KinematicState(robot, q, v)
api("robots", "zero quaternion", lambda: state(lambda q, v: q.__setitem__(slice(3, 7), 0.0)), "quaternion")
api("robots", "quaternion of norm 2", lambda: state(lambda q, v: q.__setitem__(slice(3, 7), [0, 0, 0, 2.0])), "norm")
api("robots", "NaN q", lambda: state(lambda q, v: q.__setitem__(10, np.nan)), "q")
api("robots", "inf q", lambda: state(lambda q, v: q.__setitem__(10, np.inf)), "q")
api("robots", "NaN v", lambda: state(lambda q, v: v.__setitem__(3, np.nan)), "v")
api("robots", "q of wrong size", lambda: KinematicState(robot, np.zeros(5), np.zeros(robot.nv)), "q")
api("robots", "v of wrong size", lambda: KinematicState(robot, robot.q0, np.zeros(3)), "v")
chain = spatial_chain(3)
api("robots", "joint_limit_violation NaN q", lambda: joint_limit_violation(chain, [0, np.nan, 0]), "q")
api("robots", "joint_limit_violation wrong size", lambda: joint_limit_violation(chain, np.zeros(5)), "q")
lo, hi, _ = chain.joint_limits()
api("robots", "q 1e6 past a limit: accepted, reported",
    lambda: joint_limit_violation(chain, [0, hi[1] + 1e6, 0]) if KinematicState(chain, [0, hi[1] + 1e6, 0], np.zeros(3)) else None,
    check=lambda v: abs(v - 1e6) < 1)
from prioik.robots import Reference, StepTasks, frame_position, posture


def build(state, t):
    tip = frame_position(state, "tip", Reference(np.array([0.5, 0.2, 0.3]), np.zeros(3), np.zeros(3)), name="tip")
    return StepTasks(TaskStack([tip.acceleration(25.0, 10.0), posture(state, chain.q0).acceleration(1.0, 2.0)]))

def bad_after(bad, at=3):
    calls = []
    def solve(stack, **kw):
        calls.append(1)
        if len(calls) <= at:
            return SimpleNamespace(x=np.zeros(stack.n), status="optimal")
        return bad(stack)
    return solve

def raising(s):
    raise RuntimeError("solver exploded")

for name, bad, word in (("solver raises", raising, "exploded"),
                        ("NaN answer called optimal", lambda s: SimpleNamespace(x=np.full(s.n, np.nan), status="optimal"), "non-finite"),
                        ("wrong-length x", lambda s: SimpleNamespace(x=np.zeros(s.n + 1), status="optimal"), "shape"),
                        ("x is None", lambda s: SimpleNamespace(x=None, status="optimal"), "shape"),
                        ("unknown status", lambda s: SimpleNamespace(x=np.zeros(s.n), status="great"), "great")):
    api("robots", f"simulate: {name}", lambda: simulate(chain, build, bad_after(bad), duration=0.2, dt=0.01),
        check=lambda r, word=word: r.failed and r.steps == 3 and word in r.message)
api("robots", "simulate duration=inf", lambda: simulate(chain, build, None, duration=float("inf"), dt=0.01), "duration",
    check=lambda r: False)
api("robots", "simulate dt > duration", lambda: simulate(chain, build, None, duration=0.01, dt=0.1), "dt",
    check=lambda r: False)

from prioik.robots import com_region, frame_region, polygon_region

free = KinematicState(chain, chain.q0, np.zeros(3), drift=False)
for name, fn, word in (
        ("region: zero normal", lambda: com_region(free, [[0, 0, 0]], upper=1.0, dt=0.01), "normal 0"),
        ("region: NaN bound", lambda: com_region(free, [[1, 0, 0]], upper=np.nan, dt=0.01), "upper"),
        ("region: lower > upper", lambda: frame_region(free, "tip", [[1, 0, 0]], 2.0, 1.0, dt=0.01), "lower"),
        ("region: no finite bound", lambda: frame_region(free, "tip", [[1, 0, 0]], dt=0.01), "no finite bound"),
        ("region: dt = 0", lambda: com_region(free, [[1, 0, 0]], upper=1.0, dt=0.0), "dt"),
        ("region: normals 2 wide", lambda: com_region(free, [[1, 0]], upper=1.0, dt=0.01), "normals"),
        ("region: normals a string", lambda: com_region(free, "abc", upper=1.0, dt=0.01), "normals"),
        ("region: dt a string", lambda: com_region(free, [[1, 0, 0]], upper=1.0, dt="x"), "dt"),
        ("region: offset a string", lambda: frame_region(free, "tip", [[1, 0, 0]], upper=1.0, dt=0.01, offset="x"), "offset"),
        ("polygon of collinear points", lambda: polygon_region([[0, 0], [1, 1], [2, 2]]), "no area"),
        ("polygon margin past its inradius", lambda: polygon_region([[0, 0], [1, 0], [0, 1]], margin=1.0), "margin")):
    api("robots", name, fn, word)

# ---------------------------------------------------------------- the compiled core
import prioik._core as core

good_A, good_b, good_w = np.ones((4, 3)), np.ones(4), np.ones(4)
ej = core.ExtendedJacobian([0, 2, 4], 3, rcond=1e-10)
def nan_at(a, i):
    a = a.copy(); a[i] = np.nan; return a
for name, args, word in (
        ("A float32", (good_A.astype(np.float32), good_b, good_w), "A must be float64"),
        ("A int", (good_A.astype(int), good_b, good_w), "A must be float64"),
        ("A list", (good_A.tolist(), good_b, good_w), "A must be a float64"),
        ("A None", (None, good_b, good_w), "A must be a float64"),
        ("A wrong shape", (np.ones((3, 4)), good_b, good_w), "A must have shape"),
        ("A Fortran order", (np.asfortranarray(np.arange(12.0).reshape(4, 3)), good_b, good_w), "C-contiguous"),
        ("A strided view", (np.ones((4, 6))[:, ::2], good_b, good_w), "C-contiguous"),
        ("A empty", (np.ones((0, 3)), good_b, good_w), "A is empty"),
        ("A NaN", (nan_at(good_A, (1, 2)), good_b, good_w), "A[1, 2]"),
        ("b inf", (good_A, np.array([1.0, np.inf, 1.0, 1.0]), good_w), "b[1]"),
        ("sqrt_weight 0", (good_A, good_b, np.array([1.0, 1.0, 0.0, 1.0])), "sqrt_weight[2]"),
        ("x float32", (good_A, good_b, good_w, np.ones(3, dtype=np.float32)), "x must be float64"),
        ("ranks float", (good_A, good_b, good_w, None, None, np.ones(2)), "ranks must be int64")):
    api("core", f"ExtendedJacobian.solve {name}", lambda args=args: ej.solve(*args), word)
api("core", "ExtendedJacobian.solve_batch A 2-D", lambda: ej.solve_batch(good_A, good_b, good_w), "A must have 3")
api("core", "ExtendedJacobian starts decreasing", lambda: core.ExtendedJacobian([0, 3, 2], 3, rcond=1e-10), "non-decreasing")
def nan_in_task():
    stack = S(np.eye(2), [1.0, 2.0])
    data = stack.data.copy()
    data.A[0, 0] = np.nan
    return F.prepare(stack.layout, "extended_jacobian", kernel="cpp").solve(data)
api("core", "prepare(kernel='cpp') on NaN data", nan_in_task, "task 'a'")
active = core.ActiveSetSolver(3, np.array([0, 2, 4]), np.array([1, 1, 0, 0], dtype=np.int8),
                              1e-9, 1e-10, 1e-12, 500, True)
lo, up = -np.ones(4), np.ones(4)
for name, args, word in (
        ("A float32", (good_A.astype(np.float32), good_b, lo, up, good_w), "A must be float64"),
        ("A list", (good_A.tolist(), good_b, lo, up, good_w), "A must be a float64"),
        ("A wrong shape", (np.ones((3, 4)), good_b, lo, up, good_w), "A must have shape"),
        ("A Fortran order", (np.asfortranarray(np.arange(12.0).reshape(4, 3)), good_b, lo, up, good_w), "C-contiguous"),
        ("lower empty", (good_A, good_b, lo[:0], up, good_w), "lower is empty"),
        ("upper strided", (good_A, good_b, lo, np.ones(8)[::2], good_w), "upper must be C-contiguous"),
        ("A NaN", (nan_at(good_A, (1, 2)), good_b, lo, up, good_w), "A[1, 2]"),
        ("lower NaN", (good_A, good_b, nan_at(lo, 3), up, good_w), "lower[3]"),
        ("sqrt_weight 0", (good_A, good_b, lo, up, np.array([1.0, 1.0, 0.0, 1.0])), "sqrt_weight[2]")):
    api("core", f"ActiveSetSolver.solve {name}", lambda args=args: active.solve(*args), word)
api("core", "ActiveSetSolver starts decreasing",
    lambda: core.ActiveSetSolver(3, np.array([0, 3, 2]), np.ones(2, dtype=np.int8), 1e-9, 1e-10, 1e-12, 500, True),
    "starts")
def nan_in_active_set_task():
    stack = TaskStack([[Task("a", np.eye(2), [1.0, 2.0])], [Task("box", np.eye(2), lower=-np.ones(2), upper=np.ones(2))]])
    data = stack.data.copy()
    data.A[0, 0] = np.nan
    return F.prepare(stack.layout, "hierarchical_active_set", kernel="cpp").solve(data)
api("core", "prepare(hierarchical_active_set, kernel='cpp') on NaN data", nan_in_active_set_task, "task 'a'")
# the row writers (prioik._core.rows): a valid frame_rows call, one argument spoilt
R = core.rows
frame = dict(A=np.zeros((6, 4)), Q=np.zeros((6, 6)), J=np.ones((6, 4)), t=np.zeros(3),
             R=np.eye(3), spec=np.array([0, 2, 1, 0, 3]), geo=np.zeros((5, 3)),
             aj=np.zeros(6), vj=np.zeros(6), x=np.zeros(3), xd=np.zeros(3), xdd=np.zeros(3),
             Rstar=np.eye(3), w=np.zeros(3), wd=np.zeros(3))
for name, key, value, word in (
        ("A list", "A", np.zeros((6, 4)).tolist(), "A must be a writable float64"),
        ("A read-only", "A", np.zeros((6, 4)).view(), "A must be a writable"),
        ("J float32", "J", np.ones((6, 4), dtype=np.float32), "J must be float64"),
        ("J wrong columns", "J", np.ones((6, 5)), "J must have shape"),
        ("spec float", "spec", np.array([0.0, 2, 1, 0, 3]), "spec must be int64"),
        ("spec column 9", "spec", np.array([0, 2, 1, 0, 9]), "spec[4] = 9"),
        ("spec rows past A", "spec", np.array([3, 2, 1, 0]), "outside A's 6 rows"),
        ("x None", "x", None, "x must be a float64"),
        ("Rstar 2-D of 2", "Rstar", np.eye(2), "Rstar must have shape")):
    bad = dict(frame, **{key: value})
    if name == "A read-only":
        bad["A"].setflags(write=False)
    api("core", f"rows.frame_rows {name}", lambda bad=bad: R.frame_rows(**bad), word)
api("core", "rows.posture_error iq past q", lambda: R.posture_error(
    np.zeros((6, 3)), 0, np.zeros(4), np.zeros(4), np.array([0, 4])), "iq[1] = 4")
api("core", "rows.state_is_valid unit odd", lambda: R.state_is_valid(
    np.ones(4), np.ones(3), np.array([0, 4, 1]), 1e-6), "unit must hold")
api("core", "rows.bounds_at row start 0.5", lambda: R.bounds_at(
    np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.array([0, 1, 2]),
    np.zeros((3, 3)), np.array([0.5, 0.1, 0.1, 1, 1, 0]), np.zeros(3)), "params[0]")

# ---------------------------------------------------------------- CLI
tmp = tempfile.mkdtemp()
good = {"levels": [[{"name": "t", "A": [[1.0, 2.0]], "b": [1.0]}]]}
def file(name, content):
    p = os.path.join(tmp, name)
    with open(p, "wb" if isinstance(content, bytes) else "w") as fh:
        fh.write(content)
    return p
gp = file("good.json", json.dumps(good))
cases = [
    ("-o damping=abc", ["solve", gp, "-o", "damping=abc"], 2, "damping"),
    ("-o rcond=-1", ["solve", gp, "-o", "rcond=-1"], 2, "rcond"),
    ("-o dampnig=1 (unknown option)", ["solve", gp, "-o", "dampnig=1"], 2, "dampnig"),
    ("-o novalue", ["solve", gp, "-o", "novalue"], 2, "novalue"),
    ("-f magic", ["solve", gp, "-f", "magic"], 2, "magic"),
    ("missing file", ["solve", os.path.join(tmp, "missing.json")], 2, "missing.json"),
    ("invalid JSON", ["solve", file("broken.json", "{ not json")], 2, "broken.json"),
    ("400-digit integer", ["solve", file("big.json", '{"levels": [[{"A": [[' + "9" * 400 + ']], "b": [1]}]]}')], 2, "big.json"),
    ("100,000-deep brackets", ["solve", file("deep.json", '{"levels": ' + "[" * 100000 + "]" * 100000 + "}")], 2, "deep.json"),
    ("unknown top-level key", ["solve", file("unk.json", json.dumps({**good, "extra": 1}))], 2, "extra"),
    ("unknown task key", ["solve", file("unkt.json", json.dumps({"levels": [[{"A": [[1]], "b": [1], "B": 1}]]}))], 2, "B"),
    ('"format": 2', ["solve", file("fmt.json", json.dumps({**good, "format": 2}))], 2, "format"),
    ("binary garbage", ["solve", file("bin.json", b"\x89PNG\r\n\x1a\n\x00\xff\xfe")], 2, "bin.json"),
    ("NaN in b", ["solve", file("nan.json", '{"levels": [[{"name": "arm", "A": [[1.0]], "b": [NaN]}]]}')], 2, "arm"),
    ("string in A", ["solve", file("str.json", '{"levels": [[{"name": "s", "A": [["1"]], "b": [1]}]]}')], 2, "'s'"),
    ("compare --formulations foo", ["compare", gp, "--formulations", "foo", "--repeats", "1"], 2, "foo"),
]
for name, argv, code, word in cases:
    res = subprocess.run([sys.executable, "-m", "prioik.cli", *argv], capture_output=True, text=True, timeout=600)
    err = res.stderr.strip()
    ok = res.returncode == code and len(err.splitlines()) == 1 and word in err
    rows.append(("CLI", name, ok, f"exit {res.returncode}, stderr {len(err.splitlines())} lines: {err[-90:]!r}"))
proc = subprocess.Popen([sys.executable, "-m", "prioik.cli", "solve", gp], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
proc.stdout.close()
err = proc.stderr.read().decode()
code = proc.wait(timeout=600)
rows.append(("CLI", "closed pipe (| head -0)", code == 0 and not err.strip(), f"exit {code}, stderr {err.strip()[-90:]!r}"))

json.dump(rows, open(sys.argv[1], "w"), indent=0)
for g in ("API", "API options (lead)", "robots", "core", "CLI"):
    sel = [r for r in rows if r[0] == g]
    print(f"{g}: {sum(r[2] for r in sel)} / {len(sel)}")
