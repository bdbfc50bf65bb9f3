"""prioik.errors: PrioikError is the base of every exception class the package defines
(found by walking the package's modules, so a new class without it fails here), each
keeps its builtin base, and one representative bad call per class raises it."""

import importlib
import inspect
import pkgutil
import threading

import numpy as np
import pytest

import prioik
from prioik import PrioikError, extras
from prioik.formulations.base import CoreInputError

#: modules that are not imported here: the compiled extensions and TSID's runner (a
#: script run by the TSID environment's python); the formulation plugins the registry
#: says cannot run here are left out too (:func:`unavailable_plugins`)
NOT_IMPORTED = {"prioik.prioik", "prioik._core", "prioik._lexls",
                "prioik.benchmarks.tsid_runner"}


def unavailable_plugins() -> set[str]:
    """The modules of the registered formulations that cannot be imported here (the
    registry's reason says why: a missing extra, or lexls built without its headers)."""
    from prioik.formulations import available
    from prioik.formulations.registry import PLUGINS
    return {PLUGINS[f.name][0] for f in available() if not f.available}


def _package_modules():
    """Every module of the installed package (imported: the full venv has every extra).
    An editable install also puts the source tree on ``prioik.__path__``, where the
    folder ``prioik/`` is the package itself: it is skipped."""
    skip = NOT_IMPORTED | unavailable_plugins()
    names = {"prioik"}
    for info in pkgutil.iter_modules(prioik.__path__, "prioik."):
        if info.name in skip:
            continue
        names.add(info.name)
        if info.ispkg:
            package = importlib.import_module(info.name)
            names.update(sub.name for sub in pkgutil.walk_packages(package.__path__,
                                                                   info.name + ".")
                         if sub.name not in skip)
    return [importlib.import_module(name) for name in sorted(names)]


def _exception_classes():
    found = {}
    for module in _package_modules():
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if issubclass(obj, BaseException) and obj.__module__.startswith("prioik"):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


#: every exception class the package defines, with the builtin base it keeps
BUILTIN_BASES = {
    "prioik.errors.UnknownNameError": KeyError,
    "prioik.hierarchy.errors.TaskStackError": ValueError,
    "prioik.hierarchy.errors.UnsupportedTaskError": ValueError,
    "prioik.formulations.base.FormulationError": ValueError,
    "prioik.formulations.base.CoreInputError": ValueError,
    "prioik.formulations.base.ConcurrentUseError": RuntimeError,
    "prioik.extras.MissingExtraError": ImportError,
    "prioik.robots.models.StateError": ValueError,
    "prioik.robots.models.ModelNotFoundError": FileNotFoundError,
    "prioik.robots.models.RobotModelError": ValueError,
    "prioik.robots.simulate.SimulationError": ValueError,
    "prioik.robots.mujoco_model.MujocoModelError": ValueError,
    "prioik.benchmarks.sweep.config.SweepConfigError": ValueError,
    "prioik.benchmarks.tsid_baseline.TsidError": RuntimeError,
    "prioik.robots.mesh_replay.MeshReplayError": ValueError,
}


def test_every_exception_class_of_the_package_is_a_prioik_error():
    found = _exception_classes()
    found.pop("prioik.errors.PrioikError")
    assert len(found) >= len(BUILTIN_BASES)
    for name, cls in found.items():
        assert issubclass(cls, PrioikError), f"{name} does not subclass PrioikError"
    # the list below is the documented one: a new class is added to it and to the docs
    assert sorted(found) == sorted(BUILTIN_BASES)
    for name, base in BUILTIN_BASES.items():
        assert issubclass(found[name], base), f"{name} lost its builtin base {base}"


def test_prioik_error_is_exported_and_documented():
    assert "PrioikError" in prioik.__all__ and prioik.PrioikError is PrioikError
    doc = prioik.errors.__doc__
    for name in BUILTIN_BASES:
        assert name.rsplit(".", 1)[1] in doc, name


def _chain_robot():
    from prioik.robots import spatial_chain
    return spatial_chain(3)


def _task_stack_error():
    prioik.TaskStack([prioik.Task("t", np.ones((2, 3)), np.ones(3))])


def _unsupported_task_error():
    stack = prioik.TaskStack([prioik.Task("box", np.eye(2), lower=-np.ones(2),
                                          upper=np.ones(2))])
    prioik.solve(stack, "extended_jacobian")


def _formulation_error():
    prioik.solve(prioik.Task("t", np.eye(2), np.ones(2)) / prioik.Task("u", np.eye(2),
                                                                    np.ones(2)), "nosuch")


def _core_input_error():
    from prioik._core import rows
    rows.velocity_targets(np.zeros(3, dtype=np.float32), np.zeros((6, 3)))


def _concurrent_use_error():
    stack = prioik.Task("t", np.eye(2), np.ones(2)) / prioik.Task("u", np.eye(2), np.ones(2))
    solver = prioik.prepare(stack.layout, "extended_jacobian")
    inside, leave = threading.Event(), threading.Event()

    def hold():
        solver._acquire(False)         # as a solve in another thread holds it
        inside.set()
        leave.wait(10.0)
        solver._release()

    worker = threading.Thread(target=hold)
    worker.start()
    inside.wait(10.0)
    try:
        solver.solve(stack)
    finally:
        leave.set()
        worker.join()


def _missing_extra_error(monkeypatch):
    real = extras._installed
    monkeypatch.setattr(extras, "_installed", lambda name: name != "pin" and real(name))
    extras.require("robots", what="this test")


def _state_error():
    from prioik.robots import KinematicState
    robot = _chain_robot()
    q = robot.q0.copy()
    q[0] = np.nan
    KinematicState(robot, q, np.zeros(robot.nv))


def _unknown_name_error():
    stack = prioik.Task("t", np.eye(2), np.ones(2)) / prioik.Task("u", np.eye(2), np.ones(2))
    stack.level_of("v")


def _robot_model_error():
    from prioik.robots import load
    load("nosuch_robot")


def _model_not_found_error():
    from prioik.robots import load
    load("nowhere/no_such_robot.urdf")


def _simulation_error():
    from prioik.robots import simulate
    robot = _chain_robot()
    simulate(robot, lambda state, t: None, None, duration=-1.0, dt=0.01)


def _mujoco_model_error():
    from prioik.robots.mujoco_model import mujoco_urdf
    mujoco_urdf("<robot")


def _tsid_error(monkeypatch):
    from prioik.benchmarks import tsid_baseline
    from prioik.robots.arm import ArmScenario
    monkeypatch.setenv(tsid_baseline.PYTHON_VARIABLE, "/nonexistent/venv/bin/python")
    tsid_baseline.run_tsid(ArmScenario(), duration=0.01, dt=0.002)


def _mesh_replay_error(monkeypatch):
    from prioik.robots import write_mesh_replay
    monkeypatch.chdir(__import__("tempfile").mkdtemp())
    write_mesh_replay("chain.html", _chain_robot(), [np.zeros(3)], dt=0.01)


def _sweep_config_error():
    from prioik.benchmarks.sweep.config import plan_from_config
    plan_from_config({"nosuch_key": 1})


BAD_CALLS = {
    "TaskStackError": _task_stack_error,
    "UnsupportedTaskError": _unsupported_task_error,
    "FormulationError": _formulation_error,
    "CoreInputError": _core_input_error,
    "ConcurrentUseError": _concurrent_use_error,
    "MissingExtraError": _missing_extra_error,
    "StateError": _state_error,
    "ModelNotFoundError": _model_not_found_error,
    "UnknownNameError": _unknown_name_error,
    "RobotModelError": _robot_model_error,
    "SimulationError": _simulation_error,
    "MujocoModelError": _mujoco_model_error,
    "SweepConfigError": _sweep_config_error,
    "TsidError": _tsid_error,
    "MeshReplayError": _mesh_replay_error,
}


def test_there_is_one_bad_call_per_exception_class():
    assert sorted(BAD_CALLS) == sorted(name.rsplit(".", 1)[1] for name in BUILTIN_BASES)


@pytest.mark.parametrize("name", sorted(BAD_CALLS))
def test_a_bad_call_raises_its_class_caught_as_prioik_error(name, monkeypatch):
    call = BAD_CALLS[name]
    args = (monkeypatch,) if "monkeypatch" in inspect.signature(call).parameters else ()
    with pytest.raises(PrioikError) as info:
        call(*args)
    assert type(info.value).__name__ == name, repr(info.value)
    assert str(info.value) and not str(info.value).startswith("'")   # reads as written
    assert isinstance(info.value, CoreInputError) == (name == "CoreInputError")
