"""Robot models: pinocchio models with a standing configuration and named frames.

Loaders:

* :func:`g1` — Unitree G1, 29 joints (``g1_29dof_rev_1_0.urdf`` of example-robot-data),
  floating base: ``n_q = 36``, ``n_v = 35``.
* :func:`talos` — PAL TALOS, ``talos_reduced.urdf`` with grippers and head locked
  (``pin.buildReducedModel``), floating base, ``half_sitting`` from its SRDF.
* :func:`sample_humanoid` — pinocchio's built-in sample humanoid (no files).
* :func:`spatial_chain` — an ``N``-link spatial serial chain built in code (any ``N``).

URDF files are found from the installed ``example-robot-data`` distribution (its
``cmeel.prefix/share/example-robot-data`` folder); no path is hard-coded. A missing
package or file raises :class:`ModelNotFoundError` saying what to install.

Every loader returns a :class:`RobotModel`; its pinocchio model is never mutated by
this package: :meth:`RobotModel.with_point_frame` returns a copy with one more frame.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from prioik.extras import install_hint

__all__ = ["ModelNotFoundError", "RobotModel", "example_robot_data_dir", "g1", "talos",
           "sample_humanoid", "spatial_chain", "LOADERS", "load"]


class ModelNotFoundError(FileNotFoundError):
    """A robot description (package or file) is not installed here."""


@dataclass
class RobotModel:
    """A pinocchio model with what the task builders need to know about it.

    Attributes:
        name: Short name (``"g1"``, ``"talos"``, ...).
        model: The pinocchio model (treat as read-only; copy before changing).
        q0: A standing (or neutral) configuration, ``n_q``.
        frames: Roles → frame names, e.g. ``{"left_foot": "left_ankle_roll_link"}``.
        source: Where the model came from (URDF path or ``"built in"``).
        floating_base: Whether joint 1 is a free flyer (first 6 velocity rows).
    """

    name: str
    model: pin.Model
    q0: np.ndarray
    frames: dict[str, str] = field(default_factory=dict)
    source: str = "built in"
    floating_base: bool = True

    @property
    def nq(self) -> int:
        """Configuration size."""
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        """Velocity (and acceleration) size: the number of task-stack columns."""
        return int(self.model.nv)

    @property
    def n_base(self) -> int:
        """Number of unactuated velocity rows (6 with a floating base, else 0)."""
        return 6 if self.floating_base else 0

    def data(self) -> pin.Data:
        """A fresh ``pin.Data`` for the model."""
        return self.model.createData()

    def frame_id(self, frame: str) -> int:
        """Frame index of a frame name or role; :class:`KeyError` naming it if absent."""
        cache = self.__dict__.setdefault("_frame_ids", {})
        if frame in cache:
            return cache[frame]
        name = self.frames.get(frame, frame)
        if not self.model.existFrame(name):
            raise KeyError(f"model {self.name!r} has no frame {name!r}")
        cache[frame] = int(self.model.getFrameId(name))
        return cache[frame]

    def joint_limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position lower/upper limits and velocity limits of the actuated joints.

        Returns arrays over the velocity rows ``n_base:`` (one per actuated joint of
        one degree of freedom); unlimited joints get ``∓inf``. Computed once per
        :class:`RobotModel` (copies are returned).
        """
        if "_limits" not in self.__dict__:
            self.__dict__["_limits"] = self._compute_joint_limits()
        return tuple(a.copy() for a in self.__dict__["_limits"])

    def actuated_q_index(self) -> np.ndarray:
        """Index in ``q`` of each actuated one-dof joint, ordered like ``v[n_base:]``
        (``-1`` for a velocity row without a single configuration entry)."""
        if "_q_index" not in self.__dict__:
            idx = np.full(self.nv - self.n_base, -1, dtype=int)
            m = self.model
            for j in range(1, m.njoints):
                jm = m.joints[j]
                if jm.nv == 1 and jm.nq == 1 and jm.idx_v >= self.n_base:
                    idx[jm.idx_v - self.n_base] = jm.idx_q
            self.__dict__["_q_index"] = idx
        return self.__dict__["_q_index"].copy()

    def _compute_joint_limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m = self.model
        lo = np.full(self.nv - self.n_base, -np.inf)
        hi = np.full(self.nv - self.n_base, np.inf)
        vmax = np.full(self.nv - self.n_base, np.inf)
        for j in range(1, m.njoints):
            jm = m.joints[j]
            if jm.nv != 1 or jm.idx_v < self.n_base:
                continue
            k = jm.idx_v - self.n_base
            if jm.nq == 1:
                lo[k] = m.lowerPositionLimit[jm.idx_q]
                hi[k] = m.upperPositionLimit[jm.idx_q]
            vmax[k] = m.velocityLimit[jm.idx_v]
        big = 1e10
        lo[lo < -big] = -np.inf
        hi[hi > big] = np.inf
        vmax[~(vmax > 0) | (vmax > big)] = np.inf
        return lo, hi, vmax

    def with_point_frame(self, name: str, parent: str, offset) -> "RobotModel":
        """A copy of this robot with a frame ``name`` fixed at ``offset`` in ``parent``.

        Args:
            name: New frame name (must not exist yet).
            parent: Frame (or role) it is attached to.
            offset: Position (3) of the new frame in the parent frame's coordinates,
                e.g. ``(0.5, 0, 0)`` for a sword tip 0.5 m along the hand's x axis.

        Returns:
            A new :class:`RobotModel` (the model is copied; this one is untouched)
            whose ``frames`` maps ``name`` to itself.
        """
        if self.model.existFrame(name):
            raise ValueError(f"model {self.name!r} already has a frame {name!r}")
        off = np.asarray(offset, dtype=float).reshape(-1)
        if off.shape != (3,) or not np.isfinite(off).all():
            raise ValueError(f"offset must be 3 finite numbers, got {offset!r}")
        model = self.model.copy()
        pid = self.frame_id(parent)
        pf = model.frames[pid]
        placement = pf.placement * pin.SE3(np.eye(3), off)
        model.addFrame(pin.Frame(name, pf.parentJoint, pid, placement, pin.FrameType.OP_FRAME))
        frames = dict(self.frames)
        frames[name] = name
        return RobotModel(self.name, model, self.q0.copy(), frames, self.source,
                          self.floating_base)

    def with_armature(self, armature: float) -> "RobotModel":
        """A copy of this robot with rotor inertia ``armature`` (kg·m²) on every actuated
        joint: pinocchio adds ``model.armature`` to the diagonal of ``M(q)`` (CRBA,
        ABA, RNEA); kinematics are unchanged.

        Raises:
            ValueError: ``armature`` is negative or not finite.
        """
        a = float(armature)
        if not (0.0 <= a < np.inf):
            raise ValueError(f"armature must be a finite number ≥ 0, got {armature!r}")
        model = self.model.copy()
        arm = np.array(model.armature, dtype=float)
        arm[self.n_base:] = a
        model.armature = arm
        return RobotModel(self.name, model, self.q0.copy(), dict(self.frames), self.source,
                          self.floating_base)


# ------------------------------------------------------------------ locating files
def example_robot_data_dir() -> Path:
    """The ``robots`` folder of the installed ``example-robot-data`` distribution.

    Raises:
        ModelNotFoundError: the distribution is not installed or has no such folder.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ModelNotFoundError("the robot descriptions come from the package "
                                 "example-robot-data (the `robots` extra); "
                                 f"{install_hint('robots')}") from None
    for f in dist.files or ():
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and "robots" in parts:
            i = parts.index("robots")
            root = Path(str(dist.locate_file(Path(*parts[: i + 1]))))
            if root.is_dir():
                return root
    raise ModelNotFoundError("example-robot-data is installed but its share/"
                             "example-robot-data/robots folder was not found "
                             f"(distribution at {dist.locate_file('')})")


def _robot_file(relative: str) -> Path:
    path = example_robot_data_dir() / relative
    if not path.is_file():
        raise ModelNotFoundError(f"{relative} is not in example-robot-data at {path.parent} "
                                 "(a newer or older version may lack it)")
    return path


def _set_joint(model: pin.Model, q: np.ndarray, joint: str, value: float) -> None:
    jid = model.getJointId(joint)
    if jid >= model.njoints:
        raise KeyError(f"no joint {joint!r}")
    q[model.joints[jid].idx_q] = value


def _put_feet_on_ground(model: pin.Model, q: np.ndarray, foot_frames) -> None:
    """Shift the base height so that the lowest foot frame is at ``z = 0``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    z = min(data.oMf[model.getFrameId(f)].translation[2] for f in foot_frames)
    q[2] -= z


# -------------------------------------------------------------------------- loaders
G1_URDF = "g1_description/urdf/g1_29dof_rev_1_0.urdf"

#: G1 standing posture (knees slightly bent, arms forward and down).
G1_STANDING = {
    "left_hip_pitch_joint": -0.3, "left_knee_joint": 0.6, "left_ankle_pitch_joint": -0.3,
    "right_hip_pitch_joint": -0.3, "right_knee_joint": 0.6, "right_ankle_pitch_joint": -0.3,
    "left_shoulder_pitch_joint": 0.2, "left_shoulder_roll_joint": 0.25,
    "left_elbow_joint": 0.8,
    "right_shoulder_pitch_joint": 0.2, "right_shoulder_roll_joint": -0.25,
    "right_elbow_joint": 0.8,
}


def g1() -> RobotModel:
    """Unitree G1 (29 actuated joints, floating base; ``n_v = 35``).

    ``q0`` stands with bent knees, feet flat, ankle frames at ``z = 0``. Frame roles:
    ``left_foot``/``right_foot`` (ankle roll links), ``left_hand``/``right_hand``
    (rubber hands), ``pelvis``, ``torso``.
    """
    path = _robot_file(G1_URDF)
    model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    q = pin.neutral(model)
    for joint, value in G1_STANDING.items():
        _set_joint(model, q, joint, value)
    frames = {"left_foot": "left_ankle_roll_link", "right_foot": "right_ankle_roll_link",
              "left_hand": "left_rubber_hand", "right_hand": "right_rubber_hand",
              "pelvis": "pelvis", "torso": "torso_link"}
    _put_feet_on_ground(model, q, [frames["left_foot"], frames["right_foot"]])
    return RobotModel("g1", model, q, frames, str(path))


TALOS_URDF = "talos_data/robots/talos_reduced.urdf"
TALOS_SRDF = "talos_data/srdf/talos.srdf"
TALOS_LOCKED = ("gripper_left_joint", "gripper_right_joint", "head_1_joint", "head_2_joint")


def talos() -> RobotModel:
    """TALOS reduced: ``talos_reduced.urdf`` with grippers and head locked (n_v = 34).

    ``q0`` is the SRDF ``half_sitting`` configuration.
    """
    path = _robot_file(TALOS_URDF)
    srdf = _robot_file(TALOS_SRDF)
    full = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    pin.loadReferenceConfigurations(full, str(srdf), False)
    q_full = np.array(full.referenceConfigurations["half_sitting"])
    locked = [full.getJointId(j) for j in TALOS_LOCKED if full.existJointName(j)]
    model = pin.buildReducedModel(full, locked, q_full)
    q = np.array(model.referenceConfigurations["half_sitting"]) \
        if "half_sitting" in model.referenceConfigurations else pin.neutral(model)
    frames = {"left_foot": "leg_left_6_link", "right_foot": "leg_right_6_link",
              "left_hand": "arm_left_7_link", "right_hand": "arm_right_7_link",
              "pelvis": "base_link", "torso": "torso_2_link"}
    return RobotModel("talos", model, q, frames, str(path))


def sample_humanoid() -> RobotModel:
    """Pinocchio's built-in sample humanoid (floating base, 28 joints; no files)."""
    model = pin.buildSampleModelHumanoid()
    q = pin.neutral(model)
    frames = {"left_foot": "lleg_effector_body", "right_foot": "rleg_effector_body",
              "left_hand": "larm_effector_body", "right_hand": "rarm_effector_body",
              "pelvis": "root_joint", "torso": "chest2_body"}
    return RobotModel("sample_humanoid", model, q, frames)


def spatial_chain(n_links: int, link_length: float = 0.3, seed: int = 0) -> RobotModel:
    """A fixed-base spatial serial chain of ``n_links`` revolute joints (any ``n ≥ 1``).

    Joint axes cycle through z, y, x; each link is ``link_length`` long along x with a
    point mass at its middle. ``q0`` is a seeded, non-singular bent configuration in
    ``±0.5`` rad; limits are ``±2.5`` rad and velocity limits 10 rad/s.
    """
    if not isinstance(n_links, (int, np.integer)) or n_links < 1:
        raise ValueError(f"n_links must be an integer ≥ 1, got {n_links!r}")
    model = pin.Model()
    model.name = f"chain{n_links}"
    parent = 0
    axes = (pin.JointModelRZ, pin.JointModelRY, pin.JointModelRX)
    for i in range(n_links):
        placement = pin.SE3(np.eye(3), np.array([link_length if i else 0.0, 0.0, 0.0]))
        jid = model.addJoint(parent, axes[i % 3](), placement, f"joint{i + 1}",
                             np.array([100.0]), np.array([10.0]),
                             np.array([-2.5]), np.array([2.5]))
        inertia = pin.Inertia(1.0, np.array([link_length / 2, 0, 0]),
                              np.diag([1e-3, 1e-2, 1e-2]))
        model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        model.addBodyFrame(f"link{i + 1}", jid, pin.SE3.Identity(), 0)
        parent = jid
    tip = pin.SE3(np.eye(3), np.array([link_length, 0.0, 0.0]))
    model.addFrame(pin.Frame("tip", parent, model.getFrameId(f"link{n_links}"), tip,
                             pin.FrameType.OP_FRAME))
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.5, 0.5, n_links)
    return RobotModel(f"chain{n_links}", model, q, {"tip": "tip", "base": "universe"},
                      "built in", floating_base=False)


#: name -> loader (no arguments)
LOADERS = {"g1": g1, "talos": talos, "sample_humanoid": sample_humanoid,
           "chain7": lambda: spatial_chain(7)}


def load(name: str) -> RobotModel:
    """Load a robot by name (``g1``, ``talos``, ``sample_humanoid``, ``chainN``)."""
    if name.startswith("chain") and name[5:].isdigit():
        return spatial_chain(int(name[5:]))
    if name not in LOADERS:
        raise ValueError(f"unknown robot {name!r}; known: {', '.join(LOADERS)}, chainN")
    return LOADERS[name]()
