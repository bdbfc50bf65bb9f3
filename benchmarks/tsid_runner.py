"""Run a scenario with TSID in TSID's own environment: JSON lines in, JSON lines out.

This file is executed by the python of the TSID environment (``make tsid`` builds
``.venv-tsid``: tsid 1.7.1 with pin 3.4.0), never imported by prioik: it needs only
numpy, pinocchio and tsid. :mod:`prioik.benchmarks.tsid_baseline` starts it, writes the
scenario and reads the trajectory back (protocol :data:`PROTOCOL`)::

    python tsid_runner.py < requests.jsonl > replies.jsonl

Requests, one JSON object per line on stdin:

1. the setup, answered by ``{"ready": true, "tsid": …, "pinocchio": …, "nq", "nv",
   "na"}``::

       {"protocol": 1, "urdf": "<robot …>", "floating_base": bool,
        "joint_names": [...], "q0": [...], "dt": float,
        "limits": {"lower": [...], "upper": [...], "velocity": [...],
                   "acceleration": [...]},          # over the actuated joints
        "tasks": [{"name", "kind", "frame", "role", "weight", "kp", "kd",
                   "contact": {"points": [[x, y, z], ...], "normal": [...], "mu",
                               "min_force", "max_force", "force_weight"}}, ...]}

   ``kind``: ``"frame"`` (6-D pose), ``"position"`` (3-D origin), ``"orientation"``,
   ``"com_xy"`` (horizontal centre of mass) or ``"posture"`` (actuated joints);
   ``role``: ``"contact"`` (a ``frame`` held: a TSID ``Contact6d``, a rigid contact — an
   equality constraint of TSID's first level — with its forces) or ``"weighted"`` (a
   motion task of TSID's second level, cost ``weight · ‖J q̈ − ẍ*‖²``). The joint
   position, velocity and acceleration limits are TSID's ``TaskJointPosVelAccBounds``,
   inequality constraints of the first level.

2. any number of ``{"targets": [step, ...]}``: ``step`` maps a task name to ``[x, ẋ,
   ẍ]`` (a ``frame``'s ``x`` as a 4×4 pose, its ``ẋ, ẍ`` as 6-vectors, linear then
   angular; a position's and the CoM's as 3-vectors; the posture's as ``n_q`` /
   ``n_v`` vectors), one per control step. Each step computes TSID's problem data at
   the current ``(t, q, v)`` with the references of that step, solves it with
   ``SolverHQuadProgFast`` (eiquadprog) and integrates semi-implicitly
   (``v ← v + q̈ dt``, ``q ← q ⊕ v dt``, as prioik's simulations). The reply is
   ``{"q": [...], "v": [...], "a": [...], "reference_time_s": [...],
   "solve_time_s": [...]}`` with one row per step taken (the state after it) and, if a
   step failed, ``"error": "<why>"`` (the rows before it are kept);

3. ``{"reset": true}``: back to ``q0`` at rest and ``t = 0``, answered by
   ``{"reset": true}``.

A malformed setup or request is answered by ``{"error": "<why>"}`` and the runner
exits with status 2. End of input ends the run (status 0).

The times are ``time.perf_counter`` in this process: ``reference_time_s`` setting the
tasks' references (read from the request before the step), ``solve_time_s`` ``computeProblemData``
(TSID's kinematics and
dynamics, ``pinocchio.computeAllTerms``, and every task's rows) plus the QP solve.
TSID keeps C++ references to its tasks and contacts, so this module keeps the Python
objects alive for the whole run.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import pinocchio as pin
from tsid import tsid_pywrap as tsid

#: the protocol's version (the setup's ``"protocol"``)
PROTOCOL = 1
KINDS = ("frame", "position", "orientation", "com_xy", "posture")
ROLES = ("contact", "weighted")
#: motion-task masks, linear then angular
MASKS = {"frame": (1, 1, 1, 1, 1, 1), "position": (1, 1, 1, 0, 0, 0),
         "orientation": (0, 0, 0, 1, 1, 1)}


class ProtocolError(ValueError):
    """A request the runner cannot take (its message says which field is at fault)."""


def _vector(value, size: int, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (size,) or not np.isfinite(arr).all():
        raise ProtocolError(f"{what} must be {size} finite numbers, got {np.shape(value)}")
    return arr


def _pose(value, what: str) -> pin.SE3:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (4, 4) or not np.isfinite(arr).all():
        raise ProtocolError(f"{what} must be a finite 4×4 pose, got shape {arr.shape}")
    return pin.SE3(arr[:3, :3].copy(), arr[:3, 3].copy())


class TsidRun:
    """TSID's formulation, tasks, contacts and solver for one setup, and the state."""

    def __init__(self, setup: dict) -> None:
        if setup.get("protocol") != PROTOCOL:
            raise ProtocolError(f"protocol must be {PROTOCOL}, got {setup.get('protocol')!r}")
        for key in ("urdf", "floating_base", "joint_names", "q0", "dt", "limits", "tasks"):
            if key not in setup:
                raise ProtocolError(f"the setup has no {key!r}")
        root = pin.JointModelFreeFlyer() if setup["floating_base"] else None
        model = (pin.buildModelFromXML(setup["urdf"], root) if root is not None
                 else pin.buildModelFromXML(setup["urdf"]))
        names = list(model.names)[1:]
        if names != list(setup["joint_names"]):
            raise ProtocolError(f"the URDF's joints {names} are not the scenario's "
                                f"{list(setup['joint_names'])}")
        self.robot = tsid.RobotWrapper(
            model, tsid.FLOATING_BASE_SYSTEM if root is not None else tsid.FIXED_BASE_SYSTEM,
            False)
        self.model = self.robot.model()
        self.dt = float(setup["dt"])
        if not self.dt > 0:
            raise ProtocolError(f"dt must be > 0, got {setup['dt']!r}")
        self.q0 = _vector(setup["q0"], self.model.nq, "q0")
        self.reset()
        self.formulation = tsid.InverseDynamicsFormulationAccForce("tsid", self.robot, False)
        self.formulation.computeProblemData(0.0, self.q, self.v)
        data = self.formulation.data()
        na = self.robot.na
        # every TSID object stays referenced here: TSID holds C++ references only
        self.tasks: dict[str, tuple] = {}
        self.contacts: list = []
        for spec in setup["tasks"]:
            self._add(spec, data, na)
        lim = setup["limits"]
        self.bounds = tsid.TaskJointPosVelAccBounds("joint_limits", self.robot, self.dt, False)
        self.bounds.setPositionBounds(_vector(lim["lower"], na, "limits.lower"),
                                      _vector(lim["upper"], na, "limits.upper"))
        self.bounds.setVelocityBounds(_vector(lim["velocity"], na, "limits.velocity"))
        self.bounds.setAccelerationBounds(_vector(lim["acceleration"], na,
                                                  "limits.acceleration"))
        self.formulation.addMotionTask(self.bounds, 1.0, 0, 0.0)
        self.solver = tsid.SolverHQuadProgFast("eiquadprog")
        self.solver.resize(self.formulation.nVar, self.formulation.nEq, self.formulation.nIn)

    def _add(self, spec: dict, data, na: int) -> None:
        name, kind, role = spec.get("name"), spec.get("kind"), spec.get("role")
        if kind not in KINDS:
            raise ProtocolError(f"task {name!r}: kind must be one of {KINDS}, got {kind!r}")
        if role not in ROLES:
            raise ProtocolError(f"task {name!r}: role must be one of {ROLES}, got {role!r}")
        if role == "contact" and kind != "frame":
            raise ProtocolError(f"task {name!r}: only a 'frame' task can be a contact")
        frame = spec.get("frame")
        if kind in MASKS and not self.model.existFrame(frame):
            raise ProtocolError(f"task {name!r}: the model has no frame {frame!r}")
        dim = {"frame": 6, "position": 6, "orientation": 6, "com_xy": 3,
               "posture": na}[kind]
        kp = float(spec["kp"]) * np.ones(dim)
        kd = float(spec["kd"]) * np.ones(dim)
        if role == "contact":
            c = spec["contact"]
            points = np.asarray(c["points"], dtype=float).T          # 3 × n
            contact = tsid.Contact6d(name, self.robot, frame, points,
                                     _vector(c["normal"], 3, f"{name}.normal"),
                                     float(c["mu"]), float(c["min_force"]),
                                     float(c["max_force"]))
            contact.setKp(kp)
            contact.setKd(kd)
            placement = self.robot.framePosition(data, self.model.getFrameId(frame))
            contact.setReference(placement)
            self.formulation.addRigidContact(contact, float(c["force_weight"]))
            self.contacts.append(contact)
            self.tasks[name] = (kind, contact, None)
            return
        if kind in MASKS:
            task = tsid.TaskSE3Equality(name, self.robot, frame)
            task.useLocalFrame(False)
            task.setMask(np.array(MASKS[kind], dtype=float))
            sample = tsid.TrajectorySample(12, 6)
        elif kind == "com_xy":
            task = tsid.TaskComEquality(name, self.robot)
            task.setMask(np.array([1.0, 1.0, 0.0]))
            sample = tsid.TrajectorySample(3)
        else:
            task = tsid.TaskJointPosture(name, self.robot)
            sample = tsid.TrajectorySample(na)
        task.setKp(kp)
        task.setKd(kd)
        weight = float(spec["weight"])
        if not weight > 0:
            raise ProtocolError(f"task {name!r}: weight must be > 0, got {weight!r}")
        self.formulation.addMotionTask(task, weight, 1, 0.0)
        self.tasks[name] = (kind, task, sample)

    def _reference(self, name: str, kind: str, sample, ref) -> tuple:
        """``(x, ẋ, ẍ)`` of one task's reference as TSID's sample takes them."""
        try:
            x, xd, xdd = ref
        except (TypeError, ValueError):
            raise ProtocolError(f"the reference of {name!r} must be [x, ẋ, ẍ]") from None
        if kind in MASKS:
            if kind == "frame":
                M = _pose(x, f"{name} target")
            elif kind == "position":
                M = pin.SE3(np.eye(3), _vector(x, 3, f"{name} target"))
            else:
                M = pin.SE3(_vector(x, 9, f"{name} target").reshape(3, 3), np.zeros(3))
            return (np.asarray(tsid.SE3ToVector(M)), _vector(xd, 6, f"{name} velocity"),
                    _vector(xdd, 6, f"{name} acceleration"))
        if kind == "com_xy":
            return tuple(_vector(value, 3, f"{name} {what}") for value, what in
                         ((x, "target"), (xd, "velocity"), (xdd, "acceleration")))
        nq, nv, na = self.model.nq, self.model.nv, self.robot.na
        return (_vector(x, nq, f"{name} target")[nq - na:],
                _vector(xd, nv, f"{name} velocity")[nv - na:],
                _vector(xdd, nv, f"{name} acceleration")[nv - na:])

    def references(self, steps: list) -> list:
        """Each step's references as ``[(task, sample, x, ẋ, ẍ), ...]``."""
        if not isinstance(steps, list):
            raise ProtocolError("'targets' must be a list of steps")
        out = []
        for k, refs in enumerate(steps):
            if not isinstance(refs, dict):
                raise ProtocolError(f"step {k} of 'targets' must map task names to "
                                    "references")
            row = []
            for name, (kind, task, sample) in self.tasks.items():
                if sample is None:                # a contact holds its initial pose
                    continue
                if name not in refs:
                    raise ProtocolError(f"step {k}: no reference for task {name!r}")
                row.append((task, sample, *self._reference(name, kind, sample, refs[name])))
            out.append(row)
        return out

    def reset(self) -> None:
        """Back to ``q0`` at rest, ``t = 0``."""
        self.q, self.v, self.t = self.q0.copy(), np.zeros(self.model.nv), 0.0

    def run(self, steps: list) -> dict:
        """Take one control step per entry of ``steps``; the reply (see the module)."""
        references = self.references(steps)
        out = {"q": [], "v": [], "a": [], "reference_time_s": [], "solve_time_s": []}
        model, dt = self.model, self.dt
        for row in references:
            t0 = time.perf_counter()
            for task, sample, x, xd, xdd in row:
                sample.value(x)
                sample.derivative(xd)
                sample.second_derivative(xdd)
                task.setReference(sample)
            t1 = time.perf_counter()
            hqp = self.formulation.computeProblemData(self.t, self.q, self.v)
            sol = self.solver.solve(hqp)
            t2 = time.perf_counter()
            if sol.status != 0:
                out["error"] = (f"t = {self.t:.3f} s: TSID's QP (eiquadprog) returned status "
                                f"{sol.status}")
                return out
            a = np.array(self.formulation.getAccelerations(sol))
            if not np.isfinite(a).all():
                out["error"] = f"t = {self.t:.3f} s: TSID returned non-finite accelerations"
                return out
            self.v = self.v + a * dt
            self.q = pin.integrate(model, self.q, self.v * dt)
            self.t += dt
            for key, value in (("q", self.q), ("v", self.v), ("a", a)):
                out[key].append(value.tolist())
            out["reference_time_s"].append(t1 - t0)
            out["solve_time_s"].append(t2 - t1)
        return out


def _reply(stream, message: dict) -> None:
    stream.write(json.dumps(message) + "\n")
    stream.flush()


def main(stdin=sys.stdin, stdout=sys.stdout) -> int:
    """Serve the requests on ``stdin`` (see the module); returns the exit status."""
    run = None
    for line in stdin:
        if not line.strip():
            continue
        try:
            request = json.loads(line)
            if run is None:
                run = TsidRun(request)
                _reply(stdout, {"ready": True, "tsid": _version("tsid"),
                                "pinocchio": pin.__version__, "nq": run.model.nq,
                                "nv": run.model.nv, "na": run.robot.na})
                continue
            if request.get("reset"):
                run.reset()
                _reply(stdout, {"reset": True})
            elif "targets" in request:
                _reply(stdout, run.run(request["targets"]))
            else:
                raise ProtocolError("a request after the setup must hold 'targets' or "
                                    "'reset'")
        except (ProtocolError, KeyError, TypeError, ValueError, RuntimeError) as exc:
            what = f"missing field {exc}" if isinstance(exc, KeyError) else str(exc)
            _reply(stdout, {"error": f"{type(exc).__name__}: {what}"})
            return 2
    return 0


def _version(distribution: str) -> str:
    import importlib.metadata
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - tsid is installed
        return "unknown"


if __name__ == "__main__":
    sys.exit(main())
