"""robots.mesh_replay: the robot's parts (frames, placements, decimation, point-frame
rods), the page's data, the checks on trajectories, and the page drawn in headless
chromium."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pinocchio as pin
import pytest

from prioik.robots import (
    MeshReplayError,
    StateError,
    g1,
    models,
    panda,
    sample_humanoid,
    talos,
    write_mesh_replay,
)
from prioik.robots.mesh_replay import MIN_TRIANGLES_PER_MESH, TRIANGLES, robot_parts


@pytest.fixture(scope="module")
def g1_robot():
    return g1()


@pytest.fixture(scope="module")
def talos_robot():
    return talos()


def _random_q(robot, rng):
    lo, hi, _ = robot.joint_limits()
    q = robot.q0.copy()
    q[robot.actuated_q_index()] = rng.uniform(lo, hi)
    if robot.floating_base:
        q[:3] += rng.normal(scale=0.3, size=3)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
    return q


def _urdf_placements(robot, srdf_state=None):
    """``q_robot ↦ {name: (oMg, geometry)}``: every visual's placement computed by
    pinocchio on the URDF's own (unlocked) model, locked joints at their reference."""
    args = (pin.JointModelFreeFlyer(), "root_joint") if robot.floating_base else ()
    full = pin.buildModelFromUrdf(robot.source, *args)
    visual = pin.buildGeomFromUrdf(full, robot.source, pin.GeometryType.VISUAL,
                                   package_dirs=list(robot.package_dirs))
    q_ref = pin.neutral(full)
    if srdf_state is not None:
        pin.loadReferenceConfigurations(full, str(srdf_state[0]), False)
        q_ref = full.referenceConfigurations[srdf_state[1]].copy()

    def placements(q_robot):
        q = q_ref.copy()
        for j in range(1, robot.model.njoints):
            jr = robot.model.joints[j]
            jf = full.joints[full.getJointId(robot.model.names[j])]
            q[jf.idx_q:jf.idx_q + jf.nq] = q_robot[jr.idx_q:jr.idx_q + jr.nq]
        data, gdata = full.createData(), visual.createData()
        pin.forwardKinematics(full, data, q)
        pin.updateGeometryPlacements(full, data, visual, gdata)
        return {g.name: (gdata.oMg[i].homogeneous, g) for i, g in
                enumerate(visual.geometryObjects)}
    return placements


def _check_placements(robot, parts, q, expected):
    data = robot.data()
    pin.framesForwardKinematics(robot.model, data, q)
    seen = 0
    for p in parts:
        if p.name not in expected:
            continue
        oMg, g = expected[p.name]
        if p.triangles == 0:        # a primitive: its scale is in its local placement
            oMg = oMg @ np.diag([*g.meshScale, 1.0])
        pose = data.oMf[robot.model.getFrameId(p.frame)].homogeneous @ p.local
        np.testing.assert_allclose(pose, oMg, atol=1e-9, err_msg=p.name)
        seen += 1
    assert seen == len(expected)


def test_every_visual_is_placed_as_pinocchio_places_it_on_the_urdf(g1_robot):
    parts = robot_parts(g1_robot, triangles=5_000)
    rng = np.random.default_rng(3)
    placements = _urdf_placements(g1_robot)
    for _ in range(3):
        q = _random_q(g1_robot, rng)
        _check_placements(g1_robot, parts, q, placements(q))


def test_a_robot_with_locked_joints_shows_its_locked_bodies_where_they_were_locked(
        talos_robot):
    """TALOS's grippers and head are locked at half_sitting: their meshes hang on the
    reduced model's frames, where pinocchio puts them on the full model at that state."""
    parts = robot_parts(talos_robot, triangles=5_000)
    assert any("gripper" in p.name for p in parts) and any("head" in p.name for p in parts)
    srdf = models.example_robot_data_dir() / models.TALOS_SRDF
    q = _random_q(talos_robot, np.random.default_rng(5))
    _check_placements(talos_robot, parts, q,
                      _urdf_placements(talos_robot, (srdf, "half_sitting"))(q))


def test_meshes_are_decimated_to_the_budget_and_mirrored_ones_keep_their_faces_out(
        talos_robot):
    full = robot_parts(talos_robot, triangles=10**7)
    small = robot_parts(talos_robot, triangles=8_000)
    meshes = [p for p in full if p.triangles]
    assert len(meshes) == len([p for p in small if p.triangles]) > 20
    total = sum(p.triangles for p in full)
    assert total > 100_000                      # nothing decimated under a huge budget
    n_small = sum(p.triangles for p in small)
    # quadric collapse stops short on meshes of many loose pieces: the budget is a target
    assert n_small <= 1.5 * (8_000 + MIN_TRIANGLES_PER_MESH * len(meshes)) < total / 6
    assert all(p.triangles > 0 for p in small if p.name in {m.name for m in meshes})
    # a mesh mirrored by its URDF scale (1, -1, 1) has its faces turned, so that it
    # encloses a positive volume (normals out) like its unmirrored twin
    def signed_volume(name):
        part = next(p for p in full if p.name == name)
        v, f = part.geometry.vertices.astype(float), part.geometry.faces.astype(int)
        return np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    left, right = signed_volume("leg_left_1_link_0"), signed_volume("leg_right_1_link_0")
    assert left > 0 and right == pytest.approx(left, rel=1e-3)


def test_a_point_frame_is_drawn_as_a_rod_from_its_parent():
    from prioik.robots.fencing import SWORD_LENGTH
    from prioik.robots.scenarios import make
    robot = make("fencing").robot
    rods = [p for p in robot_parts(robot, triangles=2_000) if p.name == "sword_tip_rod"]
    assert len(rods) == 1 and rods[0].frame == "sword_tip"
    rod = rods[0]
    assert rod.geometry.height == pytest.approx(SWORD_LENGTH, abs=1e-12)
    # its middle is halfway back to the hand, along the hand's x axis
    np.testing.assert_allclose(rod.local[:3, 3], [-SWORD_LENGTH / 2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(rod.local[:3, 1], [-1, 0, 0], atol=1e-12)


def _page_data(path):
    text = path.read_text()
    meshes = json.loads(re.search(r"^const MESHES = (.*);$", text, re.M).group(1))
    data = json.loads(re.search(r"^const DATA = (.*);$", text, re.M).group(1))
    return meshes, data


def _floats(b64):
    return np.frombuffer(base64.b64decode(b64), dtype="<f4").astype(float)


def test_the_page_holds_every_run_sampled_with_the_poses_of_forward_kinematics(tmp_path):
    robot = panda()
    rng = np.random.default_rng(11)
    runs = [np.array([_random_q(robot, rng) for _ in range(k)]) for k in (41, 7)]
    page = write_mesh_replay(tmp_path / "p.html", robot, runs, dt=0.01,
                             labels=["slow", "short"], fps=25,
                             markers=lambda t: {"target": np.array([0.4, 0.0, t])})
    meshes, data = _page_data(page)
    parts = robot_parts(robot)
    assert len(meshes) == 2 * len(parts)        # one object and one placement per part
    assert list(data["runs"]) == ["slow", "short"] and data["title"] == "panda"
    assert data["triangles"] == sum(p.triangles for p in parts) <= 1.5 * TRIANGLES
    run = data["runs"]["slow"]
    t = _floats(run["t"])
    rows = [0, 4, 8, 12, 16, 20, 24, 28, 32, 36, 40]          # every 4 steps at 25 fps
    np.testing.assert_allclose(t, 0.01 * np.array(rows), atol=1e-7)
    frames, k = data["frames"], len(rows)
    poses = _floats(run["frames"]).reshape(len(frames), 7 * k)
    model, d = robot.model, robot.data()
    for i, row in enumerate(rows):
        pin.framesForwardKinematics(model, d, runs[0][row])
        for c, name in enumerate(frames):
            M = d.oMf[model.getFrameId(name)]
            np.testing.assert_allclose(poses[c, 3 * i:3 * i + 3], M.translation, atol=1e-6)
            quat = poses[c, 3 * k + 4 * i:3 * k + 4 * i + 4]
            R = pin.Quaternion(quat[3], *quat[:3]).normalized().toRotationMatrix()
            np.testing.assert_allclose(R, M.rotation, atol=1e-6)
    assert run["marker_names"] == ["target"]
    np.testing.assert_allclose(_floats(run["markers"]).reshape(k, 3)[:, 2], t, atol=1e-7)
    assert len(_floats(data["runs"]["short"]["t"])) == 3         # rows 0, 4 and the last


def test_simulation_results_replay_with_their_times_and_stop_message(tmp_path):
    from prioik.robots import SimulationResult
    robot = panda()
    k = 30
    q = np.tile(robot.q0, (k, 1))
    z = np.zeros((k, robot.nv))
    res = SimulationResult(0.004 * np.arange(k), q, z, z, z, {}, np.zeros(k),
                           np.zeros(k), np.zeros(k), np.zeros(k), ["optimal"] * k,
                           failed=True, message="t = 0.12 s: the solver failed")
    page = write_mesh_replay(tmp_path / "r.html", robot, {"mine": res})
    _, data = _page_data(page)
    assert data["runs"]["mine"]["note"] == "stopped: t = 0.12 s: the solver failed"
    assert _floats(data["runs"]["mine"]["t"])[-1] == pytest.approx(0.116, abs=1e-6)


def test_malformed_trajectories_are_refused_naming_the_run(tmp_path, g1_robot):
    q = np.tile(g1_robot.q0, (5, 1))
    out = tmp_path / "x.html"
    with pytest.raises(StateError, match=r"run 'run'.*k × 36"):
        write_mesh_replay(out, g1_robot, q[:, :30], dt=0.01)
    bad = q.copy()
    bad[2, 3:7] = [0.0, 0.0, 0.0, 2.0]
    with pytest.raises(StateError, match=r"run 'b': q\[2, 3:7\].*norm 2"):
        write_mesh_replay(out, g1_robot, {"a": q, "b": bad}, dt=0.01)
    bad = q.copy()
    bad[4, 10] = np.nan
    with pytest.raises(StateError, match=r"q\[4, 10\] is nan"):
        write_mesh_replay(out, g1_robot, bad, dt=0.01)
    with pytest.raises(MeshReplayError, match="dt must be a positive"):
        write_mesh_replay(out, g1_robot, q)
    with pytest.raises(MeshReplayError, match="2 labels for 1 runs"):
        write_mesh_replay(out, g1_robot, [q], dt=0.01, labels=["a", "b"])
    with pytest.raises(MeshReplayError, match="same label"):
        write_mesh_replay(out, g1_robot, [q, q], dt=0.01, labels=["a", "a"])
    with pytest.raises(MeshReplayError, match="no URDF"):
        write_mesh_replay(out, sample_humanoid(), [sample_humanoid().q0], dt=0.01)
    with pytest.raises(MeshReplayError, match="triangles must be"):
        write_mesh_replay(out, g1_robot, q, dt=0.01, triangles=0)
    assert not out.exists()


# ---------------------------------------------------------------- in a real browser
def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _open(browser, page, tmp_path, name):
    """The page's count of drawn robot meshes (after its scripts ran) and a screenshot,
    the run paused at 0.15 s (the address's #t=)."""
    common = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
              "--window-size=900,600", "--virtual-time-budget=1500"]
    url = page.resolve().as_uri() + "#t=0.15"
    dom = subprocess.run([*common, "--dump-dom", url], check=True,
                         capture_output=True, text=True, timeout=120).stdout
    shot = tmp_path / f"{name}.png"
    subprocess.run([*common, f"--screenshot={shot}", url], check=True,
                   capture_output=True, timeout=120)
    from PIL import Image
    body = re.search(r"<body([^>]*)>", dom).group(1)
    meshes = re.search(r'data-meshes="(\d+)"', body)
    return (int(meshes.group(1)) if meshes else None,
            np.asarray(Image.open(shot).convert("RGB")).astype(int))


def test_the_meshed_page_draws_the_robot_in_headless_chromium(tmp_path):
    """Open the meshed replay of a fencing run in headless chromium: the page's scene
    holds one drawn mesh per robot part, and the screenshot differs from the same page
    without the robot's meshes in a robot-sized region in the middle of the view."""
    browser = _chromium()
    if browser is None:
        pytest.skip("chromium is not installed (.ci/run installs it)")
    from prioik.benchmarks.scenario_runs import run_one, run_table
    from prioik.robots.scenarios import make
    res = run_one(run_table("fencing")["extended_jacobian"], "compatible", 0.2, 0.002)
    scenario = make("fencing")
    page = write_mesh_replay(tmp_path / "meshes.html", scenario.robot,
                             {"extended_jacobian": res}, markers=scenario.markers)
    meshes, image = _open(browser, page, tmp_path, "robot")
    assert meshes == len(_page_data(page)[0]) // 2 > 30      # one object per part
    # the same page without the robot's meshes (markers, grid, background unchanged)
    text = page.read_text()
    empty = tmp_path / "empty.html"
    empty.write_text(re.sub(r"^const MESHES = .*;$", "const MESHES = [];", text, flags=re.M))
    meshes_empty, image_empty = _open(browser, empty, tmp_path, "empty")
    assert meshes_empty == 0
    robot = np.abs(image - image_empty).max(axis=2) > 40
    assert robot.sum() > 8_000                  # a 900 × 600 view: the robot is large
    rows, cols = np.nonzero(robot)
    assert 250 < cols.mean() < 650 and 150 < rows.mean() < 450


def test_without_the_view_extra_the_error_says_what_to_install(monkeypatch, tmp_path):
    import prioik.extras
    from prioik.extras import MissingExtraError
    monkeypatch.setattr(prioik.extras, "missing_distributions",
                        lambda extra: ("fast-simplification",) if extra == "view" else ())
    with pytest.raises(MissingExtraError, match=r"pip install prioik\[view\]"):
        write_mesh_replay(tmp_path / "x.html", panda(), [panda().q0], dt=0.01)


def test_markers_must_name_the_same_finite_points_at_every_time(tmp_path):
    robot = panda()
    q = np.tile(robot.q0, (30, 1))
    out = tmp_path / "m.html"
    with pytest.raises(MeshReplayError, match="same names"):
        write_mesh_replay(out, robot, q, dt=0.01,
                          markers=lambda t: {"a" if t < 0.1 else "b": np.zeros(3)})
    with pytest.raises(MeshReplayError, match="marker 'a' at t = 0 is not 3 numbers"):
        write_mesh_replay(out, robot, q, dt=0.01, markers=lambda t: {"a": [1.0, 2.0]})
    with pytest.raises(MeshReplayError, match="marker 'a' .* not finite"):
        write_mesh_replay(out, robot, q, dt=0.01, markers=lambda t: {"a": [np.nan, 0, 0]})
    assert not out.exists()
