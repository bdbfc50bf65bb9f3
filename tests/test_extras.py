"""prioik.extras and pyproject.toml agree; with every extra installed (as `make test`
installs them) each is found; a missing one is reported as the extra to install, by the
registry, by prioik.extras and on the command line. tests/core checks the core alone."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomllib

from prioik import cli, extras, formulations
from prioik.formulations import registry
from prioik.hierarchy.families import compatible

PYPROJECT = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml")
                          .read_text(encoding="utf-8"))["project"]


def _name(req: str) -> str:
    return re.split(r"[\s<>=!~;\[]", req, maxsplit=1)[0].lower()


def test_the_core_is_numpy_scipy_threadpoolctl_tqdm():
    assert {_name(r) for r in PYPROJECT["dependencies"]} == {"numpy", "scipy",
                                                             "threadpoolctl", "tqdm"}


def test_every_extra_of_pyproject_is_described_and_all_holds_each():
    declared = PYPROJECT["optional-dependencies"]
    assert set(declared) == set(extras.EXTRAS) | {"test", "all"}
    (everything,) = declared["all"]
    assert everything.startswith("prioik[")
    assert set(everything[len("prioik["):-1].split(",")) == set(extras.EXTRAS)


def test_every_plugin_extra_is_a_declared_one():
    for name, (_, extra) in registry.PLUGINS.items():
        assert extra == "" or extra in extras.EXTRAS, name


def test_every_extra_is_installed_here():
    # `make test` installs .[all,test]: a module name in EXTRAS that an extra does not
    # bring (a typo, a renamed package) shows here
    assert extras.installed() == list(extras.EXTRAS)


def test_a_plugin_whose_dependency_is_missing_names_its_extra(monkeypatch, tmp_path):
    (tmp_path / "needs_absent_package.py").write_text("import prioik_absent_package_x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(registry.PLUGINS, "ghost", ("needs_absent_package", "qp"))
    monkeypatch.delitem(registry._failed, "ghost", raising=False)
    info = {f.name: f for f in formulations.available()}["ghost"]
    assert not info.available and info.extra == "qp"
    assert info.reason == ("No module named 'prioik_absent_package_x' (the `qp` extra); "
                           "install it with `pip install prioik[qp]`")
    with pytest.raises(formulations.FormulationError,
                       match=r"'ghost' is not available here: .*pip install prioik\[qp\]`$"):
        formulations.solve(compatible(np.random.default_rng(0), 4, 2), "ghost")


def _hide(monkeypatch, *distributions):
    real = extras._installed
    monkeypatch.setattr(extras, "_installed",
                        lambda name: name not in distributions and real(name))


def test_missing_extras_are_named_together(monkeypatch):
    _hide(monkeypatch, "pin", "matplotlib")
    assert extras.missing_distributions("robots") == ("pin",)
    extras.require("qp", what="x")
    with pytest.raises(extras.MissingExtraError) as info:
        extras.require("robots", "qp", "plots", what="this command")
    assert info.value.extras == ("robots", "plots")
    assert str(info.value) == ("this command needs the `robots` and `plots` extras "
                               "(pin, matplotlib not installed); install them with "
                               "`pip install prioik[robots,plots]`")
    with pytest.raises(KeyError, match="unknown extra 'robot'; known: robots"):
        extras.missing_distributions("robot")


@pytest.mark.parametrize("argv, extra", [(["fencing"], "robots"), (["bench", "--quick"], "plots")])
def test_a_command_needing_a_missing_extra_prints_one_line(monkeypatch, capsys, tmp_path,
                                                          argv, extra):
    _hide(monkeypatch, extras.EXTRAS[extra][0][0])
    assert cli.main(argv + ["--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"prioik {argv[0]}: error: this command needs the `{extra}` extra "
                   f"({extras.EXTRAS[extra][0][0]} not installed); install it with "
                   f"`pip install prioik[{extra}]`")
    assert list(tmp_path.iterdir()) == []   # nothing ran


_LOADED = ("import json, sys; {setup}; print(json.dumps(sorted(m for m in sys.modules "
           "if m.split('.')[0] in {heavy})))")
#: the modules of every extra, and the heavy parts of the core (loaded on first solve)
_HEAVY = ("pinocchio", "example_robot_data", "qpsolvers", "osqp", "proxsuite", "quadprog",
          "daqp", "clarabel", "highspy", "cvxpy", "placo", "pink", "mink", "mujoco",
          "matplotlib", "meshcat", "dask", "distributed", "scipy")


@pytest.mark.parametrize("setup, allowed", [
    ("import prioik", set()),
    # the parser of every sub-command, without running one
    ("import prioik.cli as c; c.build_parser()", set()),
])
def test_importing_prioik_and_building_the_cli_load_no_heavy_module(tmp_path, setup, allowed):
    code = _LOADED.format(setup=setup, heavy=repr(set(_HEAVY)))
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, check=True)
    assert set(json.loads(out.stdout)) <= allowed
