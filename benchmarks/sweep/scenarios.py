"""What a sweep can vary, per scenario, and how a point of the sweep becomes a run.

A :class:`SweepScenario` declares its :class:`Parameter` table (name → default, kind,
range, meaning), turns a point (parameter name → value) into the fully resolved
parameters of one run (defaults filled, the target computed from a reach margin),
builds the :class:`~prioik.robots.scenario.Scenario` of those parameters on a worker,
and judges a finished run against its success criteria.

Reach margin: the distance from the shoulder joint to the target minus the arm's
length — the sum of the distances between successive joints from the shoulder to the
tip at the standing posture (sword included), an upper bound on what the arm alone
reaches. ``margin < 0``: within the arm's length; the torso's lean can add a little,
the contact, balance and joint-limit levels above the tip take some away.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

__all__ = ["Parameter", "SweepScenario", "FencingSweep", "SWEEP_SCENARIOS"]


@dataclass(frozen=True)
class Parameter:
    """One sweepable parameter.

    Attributes:
        default: Value when the sweep does not set it (``None``: unset).
        kind: ``"float"``, ``"str"`` or ``"vector3"``.
        doc: Meaning and unit.
        minimum: Smallest allowed number (inclusive; ``None``: unbounded).
        exclusive_minimum: ``minimum`` itself is not allowed.
        choices: Allowed values of a ``"str"`` parameter.
    """

    default: Any
    kind: str
    doc: str
    minimum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple[str, ...] = ()

    def check(self, name: str, value: Any) -> Any:
        """The normalised value, or ``ValueError`` naming the parameter."""
        if value is None:
            return None
        if self.kind == "str":
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise ValueError(f"parameter {name!r}: {value!r} is not one of "
                                 f"{', '.join(map(repr, self.choices))}")
            return value
        if self.kind == "vector3":
            try:
                v = [float(x) for x in value]
            except (TypeError, ValueError):
                raise ValueError(f"parameter {name!r} must be three numbers, got "
                                 f"{value!r}") from None
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise ValueError(f"parameter {name!r} must be three finite numbers, got "
                                 f"{value!r}")
            return v
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"parameter {name!r} must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"parameter {name!r} must be finite, got {value!r}")
        if self.minimum is not None and (value < self.minimum or (
                self.exclusive_minimum and value == self.minimum)):
            op = ">" if self.exclusive_minimum else "≥"
            raise ValueError(f"parameter {name!r} must be {op} {self.minimum:g}, got {value:g}")
        return value


class SweepScenario:
    """Base of the sweepable scenarios (see the module docstring)."""

    name: ClassVar[str] = ""
    robots: ClassVar[tuple[str, ...]] = ()
    parameters: ClassVar[dict[str, Parameter]] = {}
    #: criterion name → (default bound, meaning)
    criteria: ClassVar[dict[str, tuple[float, str]]] = {}
    #: the parameters fixed under ``PRIOIK_SMOKE=1`` (:mod:`prioik.smoke`): a
    #: valid run of a few steps
    smoke_parameters: ClassVar[dict[str, Any]] = {}

    def resolve(self, point: dict[str, Any]) -> dict[str, Any]:  # pragma: no cover
        raise NotImplementedError

    def build(self, params: dict[str, Any]):  # pragma: no cover
        raise NotImplementedError

    def judge(self, row: dict[str, Any], criteria: dict[str, float]
              ) -> dict[str, bool | None]:  # pragma: no cover
        raise NotImplementedError


def reach_geometry(robot, first_joint: str, tip_frame: str) -> tuple[np.ndarray, float]:
    """``(shoulder, length)``: the position of ``first_joint`` at ``robot.q0`` and the
    sum of the distances between successive joints from it to ``tip_frame``."""
    import pinocchio as pin
    m = robot.model
    d = m.createData()
    pin.framesForwardKinematics(m, d, robot.q0)
    fid = robot.frame_id(tip_frame)
    start = m.getJointId(first_joint)
    chain = []
    j = m.frames[fid].parentJoint
    while j > 0 and j != start:
        chain.append(j)
        j = m.parents[j]
    if j != start:
        raise ValueError(f"{tip_frame!r} is not below joint {first_joint!r}")
    points = [d.oMi[start].translation] + [d.oMi[k].translation for k in reversed(chain)]
    points.append(d.oMf[fid].translation)
    pts = np.array(points)
    return pts[0].copy(), float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


@lru_cache(maxsize=4)
def _fencing_robot(name: str):
    """The G1 with the sword frame, built once per process (a worker reuses it)."""
    from prioik.robots.fencing import SWORD_LENGTH
    from prioik.robots.models import g1
    if name != "g1":  # pragma: no cover - resolve() refuses other names first
        raise ValueError(f"the fencing scenario has no robot {name!r}")
    return g1().with_point_frame("sword_tip", "left_hand", (SWORD_LENGTH, 0.0, 0.0))


@lru_cache(maxsize=4)
def _fencing_reach(name: str) -> tuple[tuple[float, ...], float]:
    shoulder, length = reach_geometry(_fencing_robot(name), "left_shoulder_pitch_joint",
                                      "sword_tip")
    return tuple(float(x) for x in shoulder), length


class FencingSweep(SweepScenario):
    """The fencing scenario (:class:`prioik.robots.fencing.FencingScenario`) with its
    sword-tip target, tracking gains, step and timing as parameters."""

    name = "fencing"
    robots = ("g1",)
    parameters = {
        "robot": Parameter("g1", "str", "robot", choices=robots),
        "target": Parameter(None, "vector3", "sword-tip target, world (m); or give "
                            "reach_margin_m (+ azimuth_deg, elevation_deg)"),
        "reach_margin_m": Parameter(None, "float", "target distance from the left "
                                    "shoulder minus the arm + sword length (m)"),
        "azimuth_deg": Parameter(0.0, "float", "direction of the target from the "
                                 "shoulder: angle from forward (+x), positive to the left"),
        "elevation_deg": Parameter(0.0, "float", "direction of the target from the "
                                   "shoulder: angle above horizontal"),
        "kp": Parameter(25.0, "float", "K_p of the CoM, left-foot and sword-tip levels "
                        "(1/s²)", minimum=0.0, exclusive_minimum=True),
        "kd": Parameter(10.0, "float", "K_d of the same levels (1/s)", minimum=0.0),
        "velocity_gain": Parameter(20.0, "float", "K of the velocity-level runs (1/s)",
                                   minimum=0.0, exclusive_minimum=True),
        "step_length": Parameter(0.2, "float", "forward step of the left foot (m)"),
        "tip_start_s": Parameter(0.5, "float", "start of the sword move (s)", minimum=0.0),
        "tip_move_s": Parameter(2.0, "float", "duration of the sword move (s)",
                                minimum=0.0, exclusive_minimum=True),
        "duration": Parameter(3.0, "float", "simulated time (s)", minimum=0.0,
                              exclusive_minimum=True),
        "dt": Parameter(0.002, "float", "control step (s)", minimum=0.0,
                        exclusive_minimum=True),
    }
    smoke_parameters = {"tip_start_s": 0.0, "tip_move_s": 0.01, "duration": 0.02}
    criteria = {
        "tip_m": (1e-3, "final sword-tip error, counted when the target is reachable (m)"),
        "support_foot_m": (1e-3, "largest support-foot displacement (m)"),
        "com_m": (1e-2, "largest horizontal CoM error (m)"),
        "reachable_margin_m": (0.0, "a target counts as reachable when its reach margin "
                               "is at most this (m)"),
    }

    def resolve(self, point: dict[str, Any]) -> dict[str, Any]:
        """Every parameter of one run, validated; the target in world coordinates and
        its reach margin both filled.

        Raises:
            ValueError: naming the parameter at fault.
        """
        p = {k: spec.check(k, point.get(k, spec.default))
             for k, spec in self.parameters.items()}
        if p["target"] is not None and p["reach_margin_m"] is not None:
            raise ValueError("give either 'target' or 'reach_margin_m', not both")
        shoulder, length = _fencing_reach(p["robot"])
        shoulder = np.array(shoulder)
        if p["target"] is None:
            if p["reach_margin_m"] is None:
                from prioik.robots.fencing import TARGETS
                p["target"] = list(TARGETS["compatible"])
            else:
                dist = length + p["reach_margin_m"]
                if dist <= 0:
                    raise ValueError(f"parameter 'reach_margin_m' = {p['reach_margin_m']:g} "
                                     f"puts the target behind the shoulder (arm length "
                                     f"{length:.3f} m)")
                az, el = math.radians(p["azimuth_deg"]), math.radians(p["elevation_deg"])
                u = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                              math.sin(el)])
                p["target"] = [float(x) for x in shoulder + dist * u]
        target = np.array(p["target"])
        p["reach_margin_m"] = float(np.linalg.norm(target - shoulder) - length)
        end = p["tip_start_s"] + p["tip_move_s"]
        if p["duration"] < end:
            raise ValueError(f"parameter 'duration' = {p['duration']:g} s ends before the "
                             f"sword move does (tip_start_s + tip_move_s = {end:g} s)")
        if p["dt"] >= p["duration"]:
            raise ValueError(f"parameter 'dt' = {p['dt']:g} s is not below the duration "
                             f"{p['duration']:g} s")
        return p

    def build(self, params: dict[str, Any]):
        """The :class:`~prioik.robots.fencing.FencingScenario` of resolved ``params``."""
        from prioik.robots.fencing import FencingScenario
        kp, kd = params["kp"], params["kd"]
        gains = {"support_foot": (100.0, 20.0), "com": (kp, kd), "left_foot": (kp, kd),
                 "sword_tip": (kp, kd), "posture": (4.0, 4.0)}
        t0 = params["tip_start_s"]
        return FencingScenario("compatible", robot=_fencing_robot(params["robot"]),
                               gains=gains, step_length=params["step_length"],
                               tip_window=(t0, t0 + params["tip_move_s"]),
                               target=np.array(params["target"]))

    def judge(self, row: dict[str, Any], criteria: dict[str, float]
              ) -> dict[str, bool | None]:
        """``ok_tip`` (``None`` when the target is not reachable), ``ok_foot``,
        ``ok_com``, ``ok_divergence`` and ``success`` (all of them that apply)."""
        failed = bool(row["failed"])
        reachable = row["reach_margin_m"] <= criteria["reachable_margin_m"]

        def within(key, bound):
            v = row.get(key)
            return (not failed) and v is not None and math.isfinite(v) and v <= bound

        out = {"reachable": reachable,
               "ok_tip": within("final_tip_error_m", criteria["tip_m"]) if reachable else None,
               "ok_foot": within("max_support_foot_error_m", criteria["support_foot_m"]),
               "ok_com": within("max_com_error_m", criteria["com_m"]),
               "ok_divergence": not failed}
        out["success"] = all(out[k] for k in ("ok_tip", "ok_foot", "ok_com", "ok_divergence")
                             if out[k] is not None)
        return out


#: scenario name → its sweep adapter
SWEEP_SCENARIOS: dict[str, type[SweepScenario]] = {"fencing": FencingSweep}
