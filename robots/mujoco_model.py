"""A robot's URDF as a MuJoCo model, and its configurations in both conventions.

MuJoCo reads URDF, with four changes that :func:`mujoco_urdf` makes to the text (the
scenarios' :meth:`~robots.scenario.Scenario.urdf_text`, or the file a
:class:`~robots.models.RobotModel` was loaded from):

* every ``<visual>`` and ``<collision>`` element is dropped: their meshes are
  ``package://`` paths MuJoCo cannot resolve, and kinematics needs neither;
* every ``<mimic>`` element is dropped: pinocchio ignores it (each mimic joint is a joint
  of its own there), and so must MuJoCo for the two to have the same joints;
* a ``<mujoco><compiler fusestatic="false" discardvisual="true" balanceinertia="true"
  angle="radian"/></mujoco>`` element is added: ``fusestatic="false"`` keeps every link
  behind a fixed joint as a body of its own (``panda_hand``, ``panda_hand_tcp``, the
  fencing scenario's ``sword_tip``), so that each of pinocchio's link frames is a MuJoCo
  body with the same placement; ``balanceinertia`` accepts the inertias of
  example-robot-data that fail MuJoCo's triangle inequality (kinematics does not use them
  beyond the centre of mass, which it keeps); ``angle="radian"`` reads limits as URDF
  writes them.
* A floating base (``robot.floating_base``) is a free joint added to the root body with
  :class:`mujoco.MjSpec` (a URDF has no floating joint).

:class:`MujocoModel` maps configurations joint by joint, by name: pinocchio's free flyer
``(x, y, z, qx, qy, qz, qw)`` is MuJoCo's free joint ``(x, y, z, qw, qx, qy, qz)``;
revolute and prismatic joints are one coordinate in both; a continuous (unbounded
revolute) joint is ``(cos θ, sin θ)`` in pinocchio and ``θ`` in MuJoCo. The two models
must have the same joints (a joint locked in pinocchio must be fixed in the URDF text,
as :meth:`robots.arm.ArmScenario.urdf_text` does), else :class:`MujocoModelError`.
``mujoco`` is imported by :func:`to_mujoco` only.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from prioik.errors import PrioikError

from .models import RobotModel

__all__ = ["MujocoModelError", "MujocoModel", "mujoco_urdf", "to_mujoco", "COMPILER"]

#: the compiler settings added to the URDF (see the module docstring)
COMPILER = {"fusestatic": "false", "discardvisual": "true", "balanceinertia": "true",
            "angle": "radian"}
_DROPPED = ("visual", "collision", "mimic")


class MujocoModelError(PrioikError, ValueError):
    """A URDF MuJoCo cannot load, or a MuJoCo model whose joints do not match the
    robot's (the message names the joints)."""


def mujoco_urdf(text: str) -> str:
    """``text`` (a URDF) as MuJoCo must read it: without ``<visual>``, ``<collision>``
    and ``<mimic>`` elements, with the ``<mujoco><compiler .../></mujoco>`` element of
    :data:`COMPILER` (replacing any ``<mujoco>`` element it had).

    Raises:
        MujocoModelError: ``text`` is not XML with a ``<robot>`` root.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MujocoModelError(f"the URDF is not valid XML: {exc}") from None
    if root.tag != "robot":
        raise MujocoModelError(f"the URDF's root element is <{root.tag}>, not <robot>")
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag in _DROPPED or (parent is root and child.tag == "mujoco"):
                parent.remove(child)
    mj = ET.Element("mujoco")
    ET.SubElement(mj, "compiler", COMPILER)
    root.insert(0, mj)
    return ET.tostring(root, encoding="unicode")


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str          # "free", "scalar" or "circle"
    pin_q: int
    mj_q: int


@dataclass(repr=False)
class MujocoModel:
    """A robot as a MuJoCo model with the map between the two configuration vectors.

    Attributes:
        robot: The pinocchio robot.
        model: The ``mujoco.MjModel`` (no geometry; a body per URDF link).
        free_joint: Name of MuJoCo's free joint (``None`` for a fixed base).
    """

    robot: RobotModel
    model: Any
    free_joint: str | None
    _joints: tuple[_Joint, ...]

    def __post_init__(self) -> None:
        scalar = [j for j in self._joints if j.kind == "scalar"]
        self._pin_scalar = np.array([j.pin_q for j in scalar], dtype=int)
        self._mj_scalar = np.array([j.mj_q for j in scalar], dtype=int)
        self._circle = [(j.pin_q, j.mj_q) for j in self._joints if j.kind == "circle"]
        free = [j for j in self._joints if j.kind == "free"]
        self._free = (free[0].pin_q, free[0].mj_q) if free else None

    @property
    def joint_names(self) -> list[str]:
        """The joints both models share, in pinocchio's order."""
        return [j.name for j in self._joints]

    def to_qpos(self, q) -> np.ndarray:
        """MuJoCo's ``qpos`` of pinocchio's configuration ``q``."""
        q = np.asarray(q, dtype=float)
        qpos = np.zeros(self.model.nq)
        qpos[self._mj_scalar] = q[self._pin_scalar]
        for p, m in self._circle:
            qpos[m] = np.arctan2(q[p + 1], q[p])
        if self._free is not None:
            p, m = self._free
            qpos[m:m + 3] = q[p:p + 3]
            qpos[m + 3] = q[p + 6]
            qpos[m + 4:m + 7] = q[p + 3:p + 6]
        return qpos

    def to_q(self, qpos) -> np.ndarray:
        """pinocchio's configuration of MuJoCo's ``qpos`` (quaternion normalised)."""
        qpos = np.asarray(qpos, dtype=float)
        q = np.zeros(self.robot.nq)
        q[self._pin_scalar] = qpos[self._mj_scalar]
        for p, m in self._circle:
            q[p], q[p + 1] = np.cos(qpos[m]), np.sin(qpos[m])
        if self._free is not None:
            p, m = self._free
            quat = qpos[m + 3:m + 7] / np.linalg.norm(qpos[m + 3:m + 7])
            q[p:p + 3] = qpos[m:m + 3]
            q[p + 3:p + 6] = quat[1:]
            q[p + 6] = quat[0]
        return q

    def velocity_limits(self) -> dict[str, float]:
        """Joint name → pinocchio's velocity limit, for every one-DoF joint (the form
        ``mink.VelocityLimit`` takes)."""
        m = self.robot.model
        out = {}
        for j in self._joints:
            if j.kind != "free":
                joint = m.joints[m.getJointId(j.name)]
                out[j.name] = float(m.velocityLimit[joint.idx_v])
        return out

    def __repr__(self) -> str:
        return (f"MujocoModel(robot={self.robot.name!r}, nq={self.model.nq}, "
                f"nv={self.model.nv}, free_joint={self.free_joint!r})")


def to_mujoco(robot: RobotModel, urdf_text: str | None = None) -> MujocoModel:
    """``robot`` as a MuJoCo model, from ``urdf_text`` (default: the file it was loaded
    from) through :func:`mujoco_urdf`; a free joint named as pinocchio's root joint on
    the root body when ``robot.floating_base``.

    Raises:
        MujocoModelError: MuJoCo cannot compile the URDF, or the two models' joints
            differ (by name, kind or number).
        ImportError: ``mujoco`` is not installed.
    """
    import mujoco

    if urdf_text is None:
        if robot.source is None:
            raise MujocoModelError(f"{robot.name} has no URDF file; pass urdf_text")
        urdf_text = Path(robot.source).read_text()
    try:
        spec = mujoco.MjSpec.from_string(mujoco_urdf(urdf_text))
    except Exception as exc:       # mujoco raises ValueError with its parser's message
        raise MujocoModelError(f"MuJoCo cannot read the URDF of {robot.name}: {exc}") from None
    pm = robot.model
    free_joint = None
    if robot.floating_base:
        free_joint = pm.names[1]
        root = spec.worldbody.first_body()
        root.add_freejoint(name=free_joint)
    try:
        model = spec.compile()
    except Exception as exc:
        raise MujocoModelError(f"MuJoCo cannot compile {robot.name}: {exc}") from None
    joints, missing = [], []
    mj_names = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, i): i
                for i in range(model.njnt)}
    for jid in range(1, pm.njoints):
        name, joint = pm.names[jid], pm.joints[jid]
        if name not in mj_names:
            missing.append(name)
            continue
        k = mj_names.pop(name)
        mj_type = int(model.jnt_type[k])
        hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
        shortname = joint.shortname()
        if "FreeFlyer" in shortname and mj_type == int(mujoco.mjtJoint.mjJNT_FREE):
            kind = "free"
        elif joint.nq == 1 and mj_type in (hinge, slide):
            kind = "scalar"
        elif "RevoluteUnbounded" in shortname and mj_type == hinge:
            kind = "circle"
        else:
            raise MujocoModelError(f"joint {name!r} of {robot.name} is {shortname} in "
                                   f"pinocchio and of MuJoCo type {mj_type}")
        joints.append(_Joint(name, kind, joint.idx_q, int(model.jnt_qposadr[k])))
    if missing or mj_names:
        raise MujocoModelError(
            f"the MuJoCo model of {robot.name} has other joints than pinocchio's: "
            f"only in pinocchio {missing or 'none'}, only in MuJoCo "
            f"{sorted(mj_names) or 'none'} (fix locked joints in the URDF text)")
    return MujocoModel(robot, model, free_joint, tuple(joints))


def body_positions(mj: MujocoModel, q, bodies) -> np.ndarray:
    """World positions (rows) of ``bodies`` at pinocchio's ``q``, by MuJoCo's forward
    kinematics (a helper for checking the map against pinocchio's frames)."""
    import mujoco
    data = mujoco.MjData(mj.model)
    data.qpos[:] = mj.to_qpos(q)
    mujoco.mj_kinematics(mj.model, data)
    return np.array([data.body(b).xpos for b in bodies])


def frame_positions(robot: RobotModel, q, frames) -> np.ndarray:
    """World positions (rows) of pinocchio's ``frames`` at ``q``."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, dtype=float))
    return np.array([data.oMf[robot.model.getFrameId(f)].translation for f in frames])
