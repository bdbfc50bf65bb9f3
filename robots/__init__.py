"""Robot models and task builders (pinocchio): robot state -> hierarchy tasks.

Data flows one way: ``hierarchy`` ← ``robots``; this package never imports
``formulations`` (:func:`simulate` takes any solver callable).

Needs the ``robots`` extra (``pip install prioik[robots]``): importing it without
pinocchio raises :class:`prioik.extras.MissingExtraError` saying so.
"""

import importlib.util

from prioik.extras import MissingExtraError

if importlib.util.find_spec("pinocchio") is None:
    raise MissingExtraError(("robots",), "prioik.robots", ("pinocchio",))

from .control_step import ControlStep
from .kinds import (
    ComRegionTask,
    ComTask,
    ContactTask,
    DampingTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    FrameRegionTask,
    JointLimitsTask,
    PointTask,
    PostureTask,
)
from .mesh_replay import MeshReplayError, write_mesh_replay
from .models import (
    LOADERS,
    PANDA_FINGERS,
    ModelNotFoundError,
    RobotModel,
    StateError,
    check_configuration,
    check_velocity,
    example_robot_data_dir,
    from_urdf,
    g1,
    go2,
    has_free_flyer,
    load,
    panda,
    sample_humanoid,
    solo12,
    spatial_chain,
    talos,
    ur5,
)
from .references import Reference, Waypoints, minimum_jerk
from .rows import MODES, TASK_KINDS, RobotTask, TaskWriter, register_task_kind, task_kind
from .simulate import (
    SimulationError,
    SimulationResult,
    StepTasks,
    equality_view,
    run_to_end,
    simulate,
    simulation_steps,
)
from .tasks import (
    JointLimitActivation,
    KinematicState,
    TaskTerm,
    com_position,
    com_region,
    contact,
    frame_orientation,
    frame_pose,
    frame_position,
    frame_region,
    joint_limit_bounds,
    joint_limit_rows,
    joint_limit_violation,
    joint_velocity_bounds,
    point_position,
    polygon_region,
    posture,
)

__all__ = [
    "LOADERS", "PANDA_FINGERS", "ModelNotFoundError", "RobotModel", "StateError",
    "check_configuration", "check_velocity", "example_robot_data_dir",
    "from_urdf", "g1", "go2", "has_free_flyer", "load", "panda", "sample_humanoid", "solo12",
    "spatial_chain", "talos", "ur5", "Reference", "Waypoints", "minimum_jerk",
    "MODES", "TaskWriter", "ControlStep", "SimulationError", "SimulationResult", "StepTasks",
    "equality_view",
    "simulate", "simulation_steps", "run_to_end", "JointLimitActivation",
    "KinematicState", "TaskTerm", "com_position", "contact", "frame_orientation",
    "frame_pose", "frame_position", "joint_limit_bounds", "joint_limit_rows",
    "joint_limit_violation", "joint_velocity_bounds", "point_position", "posture",
    "frame_region", "com_region", "polygon_region", "MeshReplayError", "write_mesh_replay",
    "RobotTask", "TASK_KINDS", "register_task_kind", "task_kind", "ComRegionTask", "ComTask",
    "ContactTask", "DampingTask", "FrameOrientationTask", "FramePoseTask",
    "FramePositionTask", "FrameRegionTask", "JointLimitsTask", "PointTask", "PostureTask",
]
