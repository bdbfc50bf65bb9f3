"""README's Python examples run as written (the first one is the control loop)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_has_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_example_runs(index, capsys):
    namespace: dict = {}
    exec(compile(BLOCKS[index], f"README.md python block {index}", "exec"), namespace)
    if "sol" in namespace:
        assert namespace["sol"].status == "optimal"
        assert np.isfinite(namespace["sol"].x).all()


#: README's joint-limits loop (the block that writes the joint-limit bounds)
LIMITS_LOOP = next(b for b in BLOCKS if 'add_joint_limits' in b)
#: its damping line, the remedy for chatter out of reach
DAMPING_LINE = next(line for line in LIMITS_LOOP.splitlines() if "add_damping" in line)


def _limits_loop_speeds(source: str, steps: int, monkeypatch):
    """README's joint-limits loop run as written but for ``steps`` steps; returns every
    step's ``q̇`` and the hand's position after it."""
    import builtins

    import pinocchio as pin

    import prioik

    answers = []
    prepare = prioik.prepare

    def recording_prepare(*args, **kwargs):
        solver = prepare(*args, **kwargs)

        class Recording:
            def solve(self, data):
                sol = solver.solve(data)
                answers.append(sol.x.copy())
                return sol

        return Recording()

    monkeypatch.setattr(prioik, "prepare", recording_prepare)
    namespace = {"range": lambda n: builtins.range(steps)}
    exec(compile(source, "README.md joint-limits loop", "exec"), namespace)
    robot, dt = namespace["robot"], namespace["dt"]
    data, fid = robot.model.createData(), robot.frame_id("panda_hand")
    q, hand = robot.q0.copy(), []
    for x in answers:
        q = pin.integrate(robot.model, q, x * dt)
        pin.framesForwardKinematics(robot.model, data, q)
        hand.append(data.oMf[fid].translation.copy())
    return np.array(answers), np.array(hand)


#: the hand's target in README's joint-limits loop
HAND_TARGET = np.array(json.loads(re.search(r'"hand", np\.array\((\[[^\]]*\])\)',
                                            LIMITS_LOOP).group(1)))


@pytest.mark.parametrize("damped", [True, False])
def test_readme_limits_loop_does_not_chatter_out_of_reach(damped, monkeypatch):
    """2,500 steps of the loop as written: once the hand has stopped making progress
    (:func:`~prioik.benchmarks.out_of_reach.settled_step`), at most 2
    sign changes of any joint's q̇ per 100 steps (at least 10 such windows); without its
    damping line the joints flip between their bounds every step."""
    from prioik.benchmarks.out_of_reach import settled_step, sign_changes

    source = LIMITS_LOOP if damped else LIMITS_LOOP.replace(DAMPING_LINE + "\n", "")
    qdot, hand = _limits_loop_speeds(source, 2500, monkeypatch)
    assert qdot.shape[0] == 2500
    counts = sign_changes(qdot, settled_step(np.linalg.norm(hand - HAND_TARGET, axis=1)))
    assert counts.shape[0] >= 10
    if damped:
        assert counts.max() <= 2, counts.max(axis=1)
    else:
        assert counts.max() >= 90, counts.max(axis=1)
