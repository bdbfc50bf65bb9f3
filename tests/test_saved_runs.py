"""Saved runs (SimulationResult.save/load), their command-line replay and plots, the
self-contained HTML replay in a real headless browser, and the short reprs."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from prioik.benchmarks.scenario_runs import run_one, run_table
from prioik.robots import SimulationResult


def spec(label: str):
    return run_table("fencing")[label]


@pytest.fixture(scope="module")
def fencing_run():
    return run_one(spec("extended_jacobian"), "compatible", 0.1, 0.002)


def test_a_saved_run_reloads_identical_arrays(fencing_run, tmp_path):
    path = fencing_run.save(tmp_path / "run")
    assert path.suffix == ".npz"
    back = SimulationResult.load(path)
    for key in SimulationResult._ARRAYS:
        a, b = getattr(fencing_run, key), getattr(back, key)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), key
    assert back.errors.keys() == fencing_run.errors.keys()
    for k in back.errors:
        assert np.array_equal(back.errors[k], fencing_run.errors[k], equal_nan=True)
    assert back.statuses == fencing_run.statuses
    assert back.q_names == fencing_run.q_names and len(back.q_names) == 36
    assert back.v_names[6] == "left_hip_pitch_joint"
    assert back.info["formulation"] == "extended_jacobian"
    assert set(back.info["versions"]) == {"numpy", "pinocchio", "prioik"}
    assert (back.failed, back.message) == (fencing_run.failed, fencing_run.message)


def test_load_refuses_other_files(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, a=np.zeros(3))
    with pytest.raises(ValueError, match="not a saved SimulationResult"):
        SimulationResult.load(bad)
    res = SimulationResult(*[np.zeros(0)] * 5, {}, *[np.zeros(0)] * 4, [],
                           info={"bad": object()})
    with pytest.raises(ValueError, match="info\\['bad'\\]"):
        res.save(tmp_path / "y.npz")


def test_reprs_are_short(fencing_run):
    text = repr(fencing_run)
    assert len(text) < 300 and "50 steps" in text and "extended_jacobian" in text
    assert "<table>" in fencing_run._repr_html_()
    from prioik.robots.scenarios import make
    sc = make("fencing")
    assert len(repr(sc.robot)) < 250 and len(repr(sc)) < 120
    assert "left_hip_pitch_joint" in sc.robot._repr_html_()


def test_replay_and_plot_commands_work_on_saved_runs(fencing_run, tmp_path, capsys):
    from prioik.cli import main
    path = fencing_run.save(tmp_path / "compatible_extended_jacobian.npz")
    assert main(["replay", str(path), "--out", str(tmp_path / "r")]) == 0
    html = tmp_path / "r" / "compatible_extended_jacobian_replay.html"
    assert html.is_file() and "const DATA" in html.read_text()
    meshed = tmp_path / "r" / "compatible_extended_jacobian_replay_meshes.html"
    assert "MeshCat.Viewer" in meshed.read_text() and meshed.stat().st_size < 4e6
    assert "replay_meshes.html" in capsys.readouterr().out
    assert main(["plot", str(path), "--out", str(tmp_path / "p")]) == 0
    assert {f.name for f in (tmp_path / "p").iterdir()} >= {"compatible_tip_error.png",
                                                           "compatible_qdd.png"}
    assert main(["replay", str(tmp_path / "missing.npz")]) == 2


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_replay_page_draws_the_robot_in_headless_chromium(tmp_path):
    """Open the replay of a fencing run in Debian's chromium (headless), take a
    screenshot and count the pixels drawn in the robot's link colour: a blank page,
    a script error or a robot off the canvas gives none."""
    browser = _chromium()
    if browser is None:
        pytest.skip("chromium is not installed (.ci/run installs it)")
    from PIL import Image

    from prioik.benchmarks.replay import ROBOT_RGB, write_replay
    res = run_one(spec("extended_jacobian"), "compatible", 0.1, 0.002)
    page = write_replay(tmp_path / "replay.html", {"extended_jacobian": res}, "test")
    shot = tmp_path / "shot.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                    "--hide-scrollbars", "--window-size=900,600",
                    "--virtual-time-budget=1500", f"--screenshot={shot}",
                    page.resolve().as_uri()], check=True, capture_output=True, timeout=120)
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    robot = np.all(np.abs(img - np.array(ROBOT_RGB)) <= 2, axis=2)
    assert robot.sum() > 500
    rows, cols = np.nonzero(robot)
    # the robot is drawn inside the canvas (below the control bar), not in a corner
    assert rows.min() > 40 and 100 < cols.mean() < 800
    # an empty page (the same HTML without data) draws no robot pixels
    empty = tmp_path / "empty.html"
    empty.write_text(page.read_text().replace('"segments":', '"segments_off":'))
    shot2 = tmp_path / "shot2.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                    "--window-size=900,600", "--virtual-time-budget=1500",
                    f"--screenshot={shot2}", empty.resolve().as_uri()], capture_output=True,
                   timeout=120)
    img2 = np.asarray(Image.open(shot2).convert("RGB")).astype(int)
    assert np.all(np.abs(img2 - np.array(ROBOT_RGB)) <= 2, axis=2).sum() == 0


def test_replay_of_a_users_own_run_needs_the_robot_and_writes_the_meshed_page(tmp_path,
                                                                             capsys):
    """A run that names no scenario (a user's own loop, SimulationResult.save) is
    replayed with its meshes once --robot names its robot; without it the command says
    what to give."""
    from prioik.benchmarks.saved_runs import TRIANGLES
    from prioik.cli import main
    from prioik.robots import mesh_replay, panda
    assert TRIANGLES == mesh_replay.TRIANGLES
    robot = panda()
    k = 20
    q = robot.q0 + np.linspace(0, 0.5, k)[:, None] * np.ones(robot.nq)
    z = np.zeros((k, robot.nv))
    run = SimulationResult(0.01 * np.arange(k), q, z, z, z, {}, np.zeros(k), np.zeros(k),
                           np.zeros(k), np.zeros(k), ["optimal"] * k)
    path = run.save(tmp_path / "mine.npz")
    assert main(["replay", str(path), "--out", str(tmp_path)]) == 2
    assert "--robot" in capsys.readouterr().err
    assert main(["replay", str(path), "--out", str(tmp_path), "--robot", "panda",
                 "--triangles", "5000"]) == 0
    assert [f.name for f in tmp_path.glob("*.html")] == ["mine_replay_meshes.html"]
    assert main(["replay", str(path), "--out", str(tmp_path / "n"), "--robot", "panda",
                 "--no-meshes"]) == 2
    assert "nothing to write" in capsys.readouterr().err
