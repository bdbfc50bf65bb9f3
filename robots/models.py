"""Robot models: pinocchio models with a standing configuration and named frames.

Any robot: :func:`from_urdf` (the base — free flyer or fixed — read from the URDF/SRDF
when not given); :func:`load` takes a name or a URDF path. Named loaders, all through
:func:`from_urdf` on example-robot-data's files:

* :func:`g1` — Unitree G1, 29 joints (``g1_29dof_rev_1_0.urdf`` of example-robot-data),
  floating base: ``n_q = 36``, ``n_v = 35``.
* :func:`talos` — PAL TALOS, ``talos_reduced.urdf`` with grippers and head locked
  (``pin.buildReducedModel``), floating base, ``half_sitting`` from its SRDF.
* :func:`panda` (fixed, 7 arm + 2 finger joints), :func:`ur5` (fixed, 6),
  :func:`go2` and :func:`solo12` (quadrupeds, floating, 12 joints).
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
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from prioik.errors import PrioikError, UnknownNameError
from prioik.extras import install_hint

__all__ = ["ModelNotFoundError", "RobotModelError", "StateError", "check_configuration",
           "check_velocity",
           "RobotModel", "example_robot_data_dir", "from_urdf",
           "has_free_flyer", "g1", "talos", "panda", "ur5", "go2", "solo12", "PANDA_FINGERS",
           "sample_humanoid", "spatial_chain", "LOADERS", "load"]


class ModelNotFoundError(PrioikError, FileNotFoundError):
    """A robot description (package or file) is not installed here."""


class RobotModelError(PrioikError, ValueError):
    """A robot model that cannot be built or changed as asked: a URDF or SRDF that does
    not parse or contradicts itself, a ``q0`` or option that does not fit the model, an
    unknown robot name (the message names the file, frame or joint)."""


class StateError(PrioikError, ValueError):
    """A robot state (``q``, ``v``) is malformed: wrong size, not finite, or a joint's
    quaternion / unit complex number not of unit norm. The message names the argument,
    the entry and the joint."""


#: ``|‖quaternion‖ − 1|`` above which a configuration is refused (pinocchio uses the
#: quaternion as given: a non-unit one gives a scaled, non-orthogonal rotation).
UNIT_NORM_TOL = 1e-6

#: Joint short names -> (offset, size) of their unit-norm part within the joint's q.
_UNIT_PARTS = {"JointModelFreeFlyer": (3, 4), "JointModelSpherical": (0, 4),
               "JointModelPlanar": (2, 2), "JointModelRUBX": (0, 2),
               "JointModelRUBY": (0, 2), "JointModelRUBZ": (0, 2),
               "JointModelRevoluteUnboundedUnaligned": (0, 2)}


def check_configuration(robot: RobotModel, q, what: str = "q") -> np.ndarray:
    """``q`` as a float copy of ``n_q`` finite values with unit quaternions.

    A ``q`` outside the joint limits is accepted (the limit tasks push it back and
    :func:`~robots.tasks.joint_limit_violation` reports by how much).

    Raises:
        StateError: naming ``what``, the entry and the joint at fault.
    """
    return _check_vector(robot, q, robot.nq, what, unit=True)


def check_velocity(robot: RobotModel, v, what: str = "v") -> np.ndarray:
    """``v`` as a float copy of ``n_v`` finite values (:class:`StateError` otherwise)."""
    return _check_vector(robot, v, robot.nv, what, unit=False)


def _check_vector(robot: RobotModel, value, size: int, what: str, unit: bool
                  ) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise StateError(f"{what} cannot be read as numbers ({exc})") from None
    if arr.shape != (size,):
        raise StateError(f"{what} must have {size} entries for robot {robot.name!r}, got "
                         f"shape {arr.shape}")
    # one dot product finds NaN/inf (finite ⇒ every entry finite; it may also overflow
    # on huge finite entries, which the scan then lets through); the scan names them
    bad = np.flatnonzero(~np.isfinite(arr)) if not math.isfinite(float(arr @ arr)) else ()
    if len(bad):
        raise StateError(f"{what} holds non-finite values at entries {bad[:5].tolist()} "
                         f"({arr[bad[0]]})")
    if unit:
        for lo, size, joint in robot.unit_norm_parts():
            seg = arr[lo:lo + size]
            norm = math.sqrt(float(seg @ seg))
            if abs(norm - 1.0) > UNIT_NORM_TOL:
                raise StateError(f"{what}[{lo}:{lo + size}] (joint {joint!r}, "
                                 f"{'quaternion' if size == 4 else 'unit complex'}) has "
                                 f"norm {norm:.6g}; it must be 1 (within {UNIT_NORM_TOL:g})")
    return arr


@dataclass(repr=False)
class RobotModel:
    """A pinocchio model with what the task builders need to know about it.

    Attributes:
        name: Short name (``"g1"``, ``"talos"``, ...).
        model: The pinocchio model (treat as read-only; copy before changing).
        q0: A standing (or neutral) configuration, ``n_q``.
        frames: Roles → frame names, e.g. ``{"left_foot": "left_ankle_roll_link"}``.
        source: Where the model came from (URDF path or ``"built in"``).
        floating_base: Whether joint 1 is a free flyer (its 6 velocity rows are the
            unactuated base). ``None`` (default) reads it from the model; a value that
            contradicts the model raises :class:`ValueError` (a fixed-base arm marked
            floating would lose its first 6 joints from the posture and the limits).
        package_dirs: Folders that ``package://`` mesh paths resolve against (for
            loading geometry, e.g. a viewer); kinematics do not need them.
    """

    name: str
    model: pin.Model
    q0: np.ndarray
    frames: dict[str, str] = field(default_factory=dict)
    source: str = "built in"
    floating_base: bool | None = None
    package_dirs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        detected = has_free_flyer(self.model)
        if self.floating_base is None:
            self.floating_base = detected
        elif bool(self.floating_base) != detected:
            first = (f"joint 1 ({self.model.names[1]!r}) is a "
                     f"{self.model.joints[1].shortname()}" if self.model.njoints > 1
                     else "the model has no joint")
            raise RobotModelError(f"robot {self.name!r}: floating_base={self.floating_base!r} "
                             f"contradicts the model ({first}); a floating base is a "
                             "free-flyer joint 1 (leave floating_base=None to detect it)")
        self.floating_base = bool(self.floating_base)
        q0 = np.array(self.q0, dtype=float).reshape(-1)
        if q0.shape != (self.model.nq,) or not np.isfinite(q0).all():
            raise RobotModelError(f"robot {self.name!r}: q0 must be {self.model.nq} finite "
                             f"numbers, got shape {np.shape(self.q0)}")
        self.q0 = q0
        self.package_dirs = tuple(str(d) for d in self.package_dirs)

    @property
    def nq(self) -> int:
        """Configuration size."""
        return self.state_sizes()[1]

    @property
    def nv(self) -> int:
        """Velocity (and acceleration) size: the number of task-stack columns."""
        return self.state_sizes()[2]

    def state_sizes(self) -> tuple:
        """``(model, n_q, n_v, unit, (n_q,), (n_v,))``: the sizes read from the model once
        (a control step reads them several times; pinocchio attributes are slow to read),
        the unit-norm parts of ``q`` as one ``int64`` array ``[start_0, size_0, …]`` (for
        the compiled state check) and the shapes of ``q`` and ``v``. Recomputed if
        :attr:`model` was replaced."""
        sizes = self.__dict__.get("_state_sizes")
        if sizes is None or sizes[0] is not self.model:
            if sizes is not None:      # a replaced model: its unit-norm parts again
                self.__dict__.pop("_unit_parts", None)
            unit = np.array([v for p in self.unit_norm_parts() for v in p[:2]],
                            dtype=np.int64)
            unit.setflags(write=False)
            nq, nv = int(self.model.nq), int(self.model.nv)
            sizes = self.__dict__["_state_sizes"] = (self.model, nq, nv, unit, (nq,), (nv,))
        return sizes

    @property
    def n_base(self) -> int:
        """Number of unactuated velocity rows (6 with a floating base, else 0)."""
        return 6 if self.floating_base else 0

    def __repr__(self) -> str:
        base = "floating base" if self.floating_base else "fixed base"
        return (f"RobotModel({self.name!r}, n_q={self.nq}, n_v={self.nv}, {base}, "
                f"{self.model.njoints - 1} joints, frames: {', '.join(self.frames) or 'none'})")

    def _repr_html_(self) -> str:
        from html import escape
        rows = [("name", self.name), ("n_q, n_v", f"{self.nq}, {self.nv}"),
                ("base", "floating" if self.floating_base else "fixed"),
                ("joints", ", ".join(list(self.model.names)[1:])),
                ("frames", ", ".join(f"{k} → {v}" for k, v in self.frames.items())),
                ("source", self.source)]
        body = "".join(f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td>"
                       f"</tr>" for k, v in rows)
        return f"<table><caption>RobotModel</caption>{body}</table>"

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
            raise UnknownNameError(f"model {self.name!r} has no frame {name!r}")
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

    def unit_norm_parts(self) -> list[tuple[int, int, str]]:
        """``(start, size, joint name)`` of each unit-norm part of ``q`` (a free flyer's
        or spherical joint's quaternion, an unbounded joint's ``(cos, sin)``)."""
        if "_unit_parts" not in self.__dict__:
            m = self.model
            parts = []
            for j in range(1, m.njoints):
                jm = m.joints[j]
                part = _UNIT_PARTS.get(jm.shortname())
                if part is not None:
                    parts.append((jm.idx_q + part[0], part[1], m.names[j]))
            self.__dict__["_unit_parts"] = parts
        return self.__dict__["_unit_parts"]

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

    def with_point_frame(self, name: str, parent: str, offset) -> RobotModel:
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
            raise RobotModelError(f"model {self.name!r} already has a frame {name!r}")
        off = np.asarray(offset, dtype=float).reshape(-1)
        if off.shape != (3,) or not np.isfinite(off).all():
            raise RobotModelError(f"offset must be 3 finite numbers, got {offset!r}")
        model = self.model.copy()
        pid = self.frame_id(parent)
        pf = model.frames[pid]
        placement = pf.placement * pin.SE3(np.eye(3), off)
        model.addFrame(pin.Frame(name, pf.parentJoint, pid, placement, pin.FrameType.OP_FRAME))
        frames = dict(self.frames)
        frames[name] = name
        return RobotModel(self.name, model, self.q0.copy(), frames, self.source,
                          self.floating_base, self.package_dirs)

    def with_armature(self, armature: float) -> RobotModel:
        """A copy of this robot with rotor inertia ``armature`` (kg·m²) on every actuated
        joint: pinocchio adds ``model.armature`` to the diagonal of ``M(q)`` (CRBA,
        ABA, RNEA); kinematics are unchanged.

        Raises:
            ValueError: ``armature`` is negative or not finite.
        """
        a = float(armature)
        if not (0.0 <= a < np.inf):
            raise RobotModelError(f"armature must be a finite number ≥ 0, got {armature!r}")
        model = self.model.copy()
        arm = np.array(model.armature, dtype=float)
        arm[self.n_base:] = a
        model.armature = arm
        return RobotModel(self.name, model, self.q0.copy(), dict(self.frames), self.source,
                          self.floating_base, self.package_dirs)


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
        raise UnknownNameError(f"no joint {joint!r}")
    q[model.joints[jid].idx_q] = value


def _put_feet_on_ground(model: pin.Model, q: np.ndarray, foot_frames) -> None:
    """Shift the base height so that the lowest foot frame is at ``z = 0``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    z = min(data.oMf[model.getFrameId(f)].translation[2] for f in foot_frames)
    q[2] -= z


# ------------------------------------------------------------------------ any URDF
def has_free_flyer(model: pin.Model) -> bool:
    """Whether joint 1 of ``model`` is a free flyer attached to the world."""
    return (model.njoints > 1 and model.parents[1] == 0
            and model.joints[1].shortname() == "JointModelFreeFlyer")


def _parse_xml(path: Path, what: str) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise RobotModelError(f"{what} {path} is not valid XML: {exc}") from None


def _urdf_base(root: ET.Element, path: Path) -> tuple[bool | None, str]:
    """What a URDF says about its base: ``(True, why)`` for a floating joint on its root
    link, ``(False, why)`` for a root link named ``world`` (the robot is fixed to it),
    ``(None, why)`` when it says neither."""
    joints = root.findall("joint")
    children = {c.get("link") for j in joints for c in j.findall("child")}
    roots = [link.get("name") for link in root.findall("link")
             if link.get("name") not in children]
    for joint in joints:
        if joint.get("type") != "floating":
            continue
        parent = joint.find("parent")
        parent = parent.get("link") if parent is not None else None
        if parent not in roots:
            raise RobotModelError(f"URDF {path}: floating joint {joint.get('name')!r} hangs from "
                             f"link {parent!r}, not from the root link; only a floating "
                             "root is supported")
        return True, (f"the URDF's joint {joint.get('name')!r} is of type floating on its "
                      f"root link {parent!r}")
    if roots == ["world"]:
        return False, "the URDF's root link is 'world' (the robot is fixed to it)"
    return None, "the URDF has neither a floating root joint nor a 'world' root link"


def _srdf_base(root: ET.Element, urdf_joints: set[str], path: Path) -> tuple[bool | None, str]:
    """What an SRDF says about the base: its ``virtual_joint`` (floating or fixed), or a
    group state giving 7 values (position and quaternion) to a joint the URDF lacks."""
    for joint in root.findall("virtual_joint"):
        kind = joint.get("type")
        if kind in ("floating", "fixed"):
            return kind == "floating", (f"the SRDF's virtual joint {joint.get('name')!r} "
                                        f"is of type {kind}")
        raise RobotModelError(f"SRDF {path}: virtual joint {joint.get('name')!r} is of type "
                         f"{kind!r}; only floating and fixed bases are supported")
    for state in root.findall("group_state"):
        for joint in state.findall("joint"):
            if joint.get("name") not in urdf_joints and \
                    len((joint.get("value") or "").split()) == 7:
                return True, (f"the SRDF's group state {state.get('name')!r} gives joint "
                              f"{joint.get('name')!r}, which the URDF lacks, 7 values "
                              "(a free flyer's position and quaternion)")
    return None, "the SRDF declares no base"


#: SRDF reference configurations tried, in order, when ``q0`` is not given
DEFAULT_CONFIGURATIONS = ("standing", "half_sitting", "default", "neutral")


def from_urdf(path: str | os.PathLike, *, floating_base: bool | None = None,
              package_dirs: Sequence[str | os.PathLike] = (),
              frames: Mapping[str, str] | None = None,
              q0: np.ndarray | str | Mapping[str, float] | None = None,
              srdf: str | os.PathLike | None = None,
              locked_joints: Sequence[str] = (), name: str | None = None) -> RobotModel:
    """Load any robot from its URDF (and optionally its SRDF).

    The base is read from the files when ``floating_base`` is not given:

    * a joint of type ``floating`` on the URDF's root link → floating (pinocchio builds
      it as a free flyer);
    * a URDF whose root link is ``world`` → fixed;
    * else the SRDF, if given: a ``virtual_joint`` of type floating or fixed, or a group
      state giving 7 values (position, quaternion) to a joint the URDF lacks (the
      ``root_joint`` of example-robot-data's SRDFs) → floating;
    * else fixed: a URDF tree's root link is fixed in the world unless it says otherwise.

    A ``floating_base`` that contradicts what the files say raises :class:`ValueError`
    naming the evidence. With a floating base the free flyer is joint 1, named
    ``root_joint``, and its 6 velocity rows are not part of the posture or the limits.

    Args:
        path: URDF file.
        floating_base: ``True``: add a free flyer at the root; ``False``: fixed base;
            ``None``: detect (above).
        package_dirs: Folders ``package://`` mesh paths resolve against (kept on the
            model for loading geometry; kinematics do not need them).
        frames: Roles → frame names (e.g. ``{"tool": "tool0"}``); every frame must exist.
        q0: The reference configuration: an array of the loaded model's ``n_q`` (before
            locking), the name of an SRDF group state, or a mapping joint name → value
            applied over the default. Default: the first SRDF group state among
            :data:`DEFAULT_CONFIGURATIONS`, else ``pin.neutral``.
        srdf: SRDF file (reference configurations, base declaration).
        locked_joints: Joints fixed at their ``q0`` value and removed from the model
            (``pin.buildReducedModel``), e.g. a gripper's fingers.
        name: The robot's name (default: the URDF's ``robot`` name).

    Raises:
        ModelNotFoundError: ``path``, ``srdf`` or a package dir does not exist.
        ValueError: a contradicting ``floating_base``, a malformed file, a bad ``q0``.
        KeyError: an unknown joint (``locked_joints``, ``q0``), frame or group state.
    """
    path = _existing_file(path, "URDF")
    urdf = _parse_xml(path, "URDF")
    urdf_joints = {j.get("name") for j in urdf.findall("joint")}
    declared, why = _urdf_base(urdf, path)
    srdf_path = _existing_file(srdf, "SRDF") if srdf is not None else None
    if srdf_path is not None:
        srdf_declared, srdf_why = _srdf_base(_parse_xml(srdf_path, "SRDF"), urdf_joints,
                                             srdf_path)
        if declared is not None and srdf_declared is not None and declared != srdf_declared:
            raise RobotModelError(f"{path.name} and {srdf_path.name} disagree about the base: "
                             f"{why}, but {srdf_why}")
        if declared is None and srdf_declared is not None:
            declared, why = srdf_declared, srdf_why
    if floating_base is not None and not isinstance(floating_base, (bool, np.bool_)):
        raise RobotModelError(f"floating_base must be True, False or None, got {floating_base!r}")
    if floating_base is not None and declared is not None and bool(floating_base) != declared:
        raise RobotModelError(f"floating_base={bool(floating_base)} contradicts {path.name}: "
                         f"{why} (leave floating_base=None to use it)")
    floating = declared if declared is not None else bool(floating_base)
    try:
        if floating and not has_free_flyer_joint(urdf):
            model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer(), "root_joint")
        else:
            model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as exc:
        raise RobotModelError(f"pinocchio could not build a model from {path}: {exc}") from None
    if has_free_flyer(model) != floating:
        raise RobotModelError(f"{path}: the model built has joint 1 {model.names[1]!r} "
                         f"({model.joints[1].shortname()}), expected "
                         f"{'a free flyer' if floating else 'no free flyer'}")
    if srdf_path is not None:
        try:
            pin.loadReferenceConfigurations(model, str(srdf_path), False)
        except (RuntimeError, ValueError) as exc:
            raise RobotModelError(f"pinocchio could not read the reference configurations of "
                             f"{srdf_path}: {exc}") from None
    q = _configuration(model, q0, srdf_path)
    if locked_joints:
        model, q = _lock(model, q, locked_joints)
    dirs = []
    for d in package_dirs:
        if not Path(d).is_dir():
            raise ModelNotFoundError(f"package dir {d} is not a folder")
        dirs.append(str(d))
    frames = dict(frames or {})
    robot_name = name or model.name or path.stem
    for role, frame in frames.items():
        if not model.existFrame(frame):
            raise UnknownNameError(f"robot {robot_name!r} ({path.name}) has no frame {frame!r} "
                           f"(role {role!r})")
    return RobotModel(robot_name, model, q, frames, str(path), floating, tuple(dirs))


def has_free_flyer_joint(urdf: ET.Element) -> bool:
    """Whether a parsed URDF declares a joint of type ``floating``."""
    return any(j.get("type") == "floating" for j in urdf.findall("joint"))


def _existing_file(path, what: str) -> Path:
    p = Path(path)
    if not p.is_file():
        raise ModelNotFoundError(f"{what} file {p} does not exist")
    return p


def _configuration(model: pin.Model, q0, srdf: Path | None) -> np.ndarray:
    """``q0`` of :func:`from_urdf` as an array of ``model.nq``."""
    refs = model.referenceConfigurations
    if q0 is None or isinstance(q0, Mapping):
        base = next((np.array(refs[c]) for c in DEFAULT_CONFIGURATIONS if c in refs),
                    pin.neutral(model))
        for joint, value in (q0 or {}).items():
            _set_joint(model, base, joint, float(value))
        return base
    if isinstance(q0, str):
        if q0 not in refs:
            known = ", ".join(sorted(entry.key() for entry in refs)) or "none"
            raise UnknownNameError(f"no group state {q0!r} in "
                           f"{srdf.name if srdf else 'the model (no SRDF given)'} "
                           f"(known: {known})")
        return np.array(refs[q0])
    q = np.array(q0, dtype=float).reshape(-1)
    if q.shape != (model.nq,) or not np.isfinite(q).all():
        raise RobotModelError(f"q0 must be {model.nq} finite numbers (the loaded model's n_q, "
                         f"before locking), got shape {np.shape(q0)}")
    if has_free_flyer(model) and np.linalg.norm(q[3:7]) < 1e-9:
        raise RobotModelError("q0's base quaternion (entries 3-6) is zero")
    return q


def _lock(model: pin.Model, q: np.ndarray, joints: Sequence[str]):
    """The reduced model with ``joints`` fixed at their value in ``q``, and ``q`` of it."""
    ids = []
    for joint in joints:
        if not model.existJointName(joint):
            raise UnknownNameError(f"cannot lock joint {joint!r}: the model has no such joint")
        ids.append(model.getJointId(joint))
    reduced = pin.buildReducedModel(model, ids, q)
    parts = []
    for j in range(1, reduced.njoints):
        full = model.joints[model.getJointId(reduced.names[j])]
        parts.append(q[full.idx_q:full.idx_q + full.nq])
    q_red = np.concatenate(parts) if parts else np.zeros(0)
    return reduced, q_red


def _set_joint(model: pin.Model, q: np.ndarray, joint: str, value: float) -> None:
    if not model.existJointName(joint):
        raise UnknownNameError(f"no joint {joint!r}")
    jm = model.joints[model.getJointId(joint)]
    if jm.nq != 1:
        raise RobotModelError(f"joint {joint!r} has {jm.nq} configuration entries; give it in a "
                         "q0 array")
    q[jm.idx_q] = value


def _put_feet_on_ground(robot: RobotModel, roles) -> RobotModel:
    """Shift the base height of ``robot.q0`` so that the lowest foot frame is at
    ``z = 0`` (in place; returns the robot)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q0)
    robot.q0[2] -= min(data.oMf[robot.frame_id(r)].translation[2] for r in roles)
    return robot


def _example_robot(relative: str, srdf: str | None = None, **kwargs) -> RobotModel:
    """:func:`from_urdf` on a file of example-robot-data (meshes resolve against it)."""
    return from_urdf(_robot_file(relative), srdf=_robot_file(srdf) if srdf else None,
                     package_dirs=(example_robot_data_dir().parent.parent,), **kwargs)


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

    Its URDF declares no base (the floating joint there is commented out), so the free
    flyer is asked for. ``q0`` stands with bent knees, feet flat, ankle frames at
    ``z = 0``. Frame roles: ``left_foot``/``right_foot`` (ankle roll links),
    ``left_hand``/``right_hand`` (rubber hands), ``pelvis``, ``torso``.
    """
    frames = {"left_foot": "left_ankle_roll_link", "right_foot": "right_ankle_roll_link",
              "left_hand": "left_rubber_hand", "right_hand": "right_rubber_hand",
              "pelvis": "pelvis", "torso": "torso_link"}
    robot = _example_robot(G1_URDF, floating_base=True, frames=frames, q0=G1_STANDING,
                           name="g1")
    return _put_feet_on_ground(robot, ("left_foot", "right_foot"))


TALOS_URDF = "talos_data/robots/talos_reduced.urdf"
TALOS_SRDF = "talos_data/srdf/talos.srdf"
TALOS_LOCKED = ("gripper_left_joint", "gripper_right_joint", "head_1_joint", "head_2_joint")


def talos() -> RobotModel:
    """TALOS reduced: ``talos_reduced.urdf`` with grippers and head locked (n_v = 34).

    The floating base is read from the SRDF (its ``half_sitting`` gives ``root_joint`` a
    position and quaternion); ``q0`` is ``half_sitting``.
    """
    frames = {"left_foot": "leg_left_6_link", "right_foot": "leg_right_6_link",
              "left_hand": "arm_left_7_link", "right_hand": "arm_right_7_link",
              "pelvis": "base_link", "torso": "torso_2_link"}
    return _example_robot(TALOS_URDF, TALOS_SRDF, frames=frames, q0="half_sitting",
                          locked_joints=TALOS_LOCKED, name="talos")


PANDA_URDF = "panda_description/urdf/panda.urdf"
PANDA_SRDF = "panda_description/srdf/panda.srdf"


def panda() -> RobotModel:
    """Franka Panda: fixed base, 7 arm joints and 2 finger joints (``n_v = 9``).

    The fingers stay in the model (the URDF's, as PlaCo and pink load it): they are
    prismatic joints with limits ``[0, 0.04]`` m, held by the posture task and the limits
    like any joint (the URDF's mimic tag is ignored: pinocchio's default). For the
    7-joint arm lock them: ``from_urdf(path, locked_joints=PANDA_FINGERS)``. ``q0`` is the
    SRDF's ``default`` (``panda_joint4 = −3π/4``, ``panda_joint6 = π/2``). Frame roles:
    ``hand`` (``panda_hand``), ``tcp`` (``panda_hand_tcp``, between the fingers).
    """
    return _example_robot(PANDA_URDF, PANDA_SRDF, name="panda",
                          frames={"hand": "panda_hand", "tcp": "panda_hand_tcp"})


PANDA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
"""The Panda's finger joints (lock them for a 7-joint arm)."""

UR5_URDF = "ur_description/urdf/ur5_robot.urdf"
UR5_SRDF = "ur_description/srdf/ur5.srdf"
#: a bent, non-singular UR5 configuration (the URDF's zero is stretched out)
UR5_HOME = {"shoulder_lift_joint": -1.2, "elbow_joint": 1.5, "wrist_1_joint": -1.9,
            "wrist_2_joint": -1.57}


def ur5() -> RobotModel:
    """Universal Robots UR5: fixed to ``world`` (read from the URDF), 6 joints.
    ``q0`` is :data:`UR5_HOME`; frame role ``tool`` (``tool0``)."""
    return _example_robot(UR5_URDF, UR5_SRDF, name="ur5", frames={"tool": "tool0"},
                          q0=UR5_HOME)


GO2_URDF = "go2_description/urdf/go2.urdf"
GO2_SRDF = "go2_description/srdf/go2.srdf"
SOLO12_URDF = "solo_description/robots/solo12.urdf"
SOLO12_SRDF = "solo_description/srdf/solo.srdf"


def go2() -> RobotModel:
    """Unitree Go2: floating base (the SRDF's virtual joint), 12 joints (``n_v = 18``).
    ``q0`` is the SRDF's ``standing`` with the feet at ``z = 0``; frame roles
    ``front_left_foot`` … ``rear_right_foot``."""
    frames = {"front_left_foot": "FL_foot", "front_right_foot": "FR_foot",
              "rear_left_foot": "RL_foot", "rear_right_foot": "RR_foot", "base": "base"}
    robot = _example_robot(GO2_URDF, GO2_SRDF, name="go2", frames=frames)
    return _put_feet_on_ground(robot, [r for r in frames if r.endswith("foot")])


def solo12() -> RobotModel:
    """Solo-12: floating base (the SRDF's ``standing`` gives ``root_joint`` a pose),
    12 joints (``n_v = 18``). ``q0`` is ``standing`` with the feet at ``z = 0``."""
    frames = {"front_left_foot": "FL_FOOT", "front_right_foot": "FR_FOOT",
              "rear_left_foot": "HL_FOOT", "rear_right_foot": "HR_FOOT",
              "base": "base_link"}
    robot = _example_robot(SOLO12_URDF, SOLO12_SRDF, name="solo12", frames=frames)
    return _put_feet_on_ground(robot, [r for r in frames if r.endswith("foot")])


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
        raise RobotModelError(f"n_links must be an integer ≥ 1, got {n_links!r}")
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


LOADERS = {"g1": g1, "talos": talos, "panda": panda, "ur5": ur5, "go2": go2,
           "solo12": solo12, "sample_humanoid": sample_humanoid,
           "chain7": lambda: spatial_chain(7)}
"""Robot name → loader (no arguments)."""


def load(robot: str | os.PathLike, **kwargs) -> RobotModel:
    """Load a robot by name or from a URDF path.

    Args:
        robot: A name (``g1``, ``talos``, ``panda``, ``ur5``, ``go2``, ``solo12``,
            ``sample_humanoid``, ``chainN``) or a URDF path (a ``Path``, or a string
            ending in ``.urdf`` or holding a path separator).
        **kwargs: For a path, :func:`from_urdf`'s options.

    Raises:
        ValueError: an unknown name, or options given with a name.
        ModelNotFoundError: the file is missing.
    """
    if isinstance(robot, os.PathLike) or (isinstance(robot, str) and (
            robot.lower().endswith(".urdf") or os.sep in robot or "/" in robot)):
        return from_urdf(robot, **kwargs)
    if not isinstance(robot, str):
        raise RobotModelError(f"robot must be a name or a URDF path, got {robot!r}")
    if kwargs:
        raise RobotModelError(f"options {sorted(kwargs)} are for a URDF path; robot {robot!r} "
                         "is a name")
    if robot.startswith("chain") and robot[5:].isdigit():
        return spatial_chain(int(robot[5:]))
    if robot not in LOADERS:
        raise RobotModelError(f"unknown robot {robot!r}; known: {', '.join(LOADERS)}, chainN, "
                         "or a URDF path")
    return LOADERS[robot]()
