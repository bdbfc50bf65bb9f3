"""The row writers' Python tests on a sanitized build of ``prioik._core``.

Run by ``make asan-bindings``: ``python core/tests/sanitized_rows.py PATH`` with
``PATH`` the extension built with ``-fsanitize=address,undefined``
(``PRIOIK_SANITIZE=ON``, ``PRIOIK_PYTHON=ON``) and the sanitizer runtimes preloaded. It
loads that build as ``prioik._core`` and runs, from ``tests/test_rows_cpp.py``, every
writer against the plain-Python reference on the Panda, G1 and TALOS at both levels, log3, the
bound and
activation formulas, the bad inputs and 40 seeds of the boundary fuzz, and from
``tests/test_control_step.py`` the control step's trajectories (Panda, G1), a capped
step, its integration and its bad inputs; a sanitizer report aborts the process.
"""

import importlib.util
import pathlib
import sys


def load_core(path: str):
    """The extension at ``path`` as ``prioik._core``, loaded before ``prioik`` is imported
    (importing it imports ``prioik._core``: the installed build's classes would then be
    the ones registered, and the sanitized build's not)."""
    spec = importlib.util.spec_from_file_location("prioik._core", path)
    core = importlib.util.module_from_spec(spec)
    sys.modules["prioik._core"] = core
    spec.loader.exec_module(core)
    import prioik
    prioik._core = core
    assert hasattr(core, "ActiveSetSolver") and hasattr(core, "ControlStep")
    return core


def main(path: str) -> None:
    core = load_core(path)
    import numpy as np

    from prioik.robots import KinematicState, TaskWriter, g1, panda, talos
    from prioik.robots import rows as rows_module
    from prioik.robots import tasks as tasks_module

    root = pathlib.Path(__file__).resolve().parents[2]
    sys.path[:0] = [str(root / "tests"), str(root)]      # the tests and their package
    import test_rows_cpp as t
    assert t.cpp_rows is core.rows and rows_module._k is core.rows

    def use(kernels):
        for module in t.WRITER_MODULES:       # robots.rows and the task kinds' modules
            module._k = kernels
        tasks_module._state_is_valid = kernels.state_is_valid

    robots = {"panda": panda(), "g1": g1(), "talos": talos()}
    for name in robots:
        for mode in ("velocity", "acceleration"):
            use(core.rows)
            t.test_every_writer_equals_the_reference(robots, lambda: use(t.reference_rows), name,
                                                    mode)
    use(core.rows)
    for theta in t.THETAS:
        t.test_log3_equals_the_reference_near_zero_and_pi(theta)
    for seed in range(20):
        t.test_bound_formulas_equal_the_reference(seed)
    for seed in range(10):
        t.test_activation_rows_equal_the_reference(seed)
    robot = robots["g1"]
    writer = TaskWriter(robot, "acceleration")
    writer.add_frame_pose("pose", "left_foot", gain=(1.0, 1.0))
    state = KinematicState(robot, robot.q0, np.zeros(robot.nv))
    _, args = writer._task("pose", "frame_pose")._frame_args(state)
    call = dict(zip(("A", "Q", "J", "t", "R", "spec", "geo", "aj", "vj"), args, strict=False))
    call.update(x=np.zeros(3), xd=np.zeros(3), xdd=np.zeros(3), Rstar=np.eye(3),
                w=np.zeros(3), wd=np.zeros(3))
    for case in t.test_bad_input_raises_prioiks_error.pytestmark[0].args[1]:
        t.test_bad_input_raises_prioiks_error(*case)
    t.test_strided_views_are_read_as_they_are(call)
    t.test_other_buffers_give_the_same_rows(call)
    for seed in range(40):
        t.test_the_bindings_refuse_or_take_any_array_without_harm(call, seed)
    # the control step (prioik._core.ControlStep) on the same build: its trajectories
    # against the writer loop, a capped step, the integration and the bad inputs
    import test_control_step as c
    c.test_panda_with_limits_equals_the_writer_loop(robots["panda"])
    c.test_g1_free_flyer_contacts_com_hand_posture_limits(robots["g1"], (0, 1))
    c.test_a_capped_step_is_the_prepared_solvers_answer(robots["panda"])
    for name in ("panda", "g1"):
        c.test_integration_is_pinocchios(name, type("R", (), {
            "getfixturevalue": staticmethod(lambda key: robots[key])})())
    c.test_bad_q(robots["g1"], robots["panda"])
    c.test_bad_references_and_declarations(robots["panda"])
    c.test_core_binding_refuses_bad_arrays(robots["panda"])
    print("sanitized prioik._core.rows: the reference, the bad inputs and 40 fuzz seeds passed;"
          " prioik._core.ControlStep: its trajectories, integration and bad inputs passed")


if __name__ == "__main__":
    main(sys.argv[1])
