"""The core alone (`pip install prioik`, no extra): it works, and every missing extra is
reported as the one to install.

Runs only in the core environment (`make test` builds .venv-core and runs this folder
there; tests/conftest.py leaves it out wherever an extra is installed).
"""

import importlib
import importlib.metadata
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import prioik
from prioik import extras, formulations
from prioik.cli import main
from prioik.formulations.registry import PLUGINS
from prioik.hierarchy import check_lexicographic, load_stack
from prioik.hierarchy.families import compatible, conflicting, random_spd, with_inequalities

EXAMPLES = Path(__file__).resolve().parents[2] / "hierarchy" / "examples"
CORE = [name for name, (_, extra) in PLUGINS.items() if not extra]
OPTIONAL = {name: extra for name, (_, extra) in PLUGINS.items() if extra}
#: lexls is built with the core only where its headers are found (PRIOIK_LEXLS_DIR)
LEXLS_BUILT = importlib.util.find_spec("prioik._lexls") is not None
CLI = [str(Path(sys.executable).with_name("prioik"))]


def _requirement_name(req: str) -> str:
    return re.split(r"[\s<>=!~;\[]", req, maxsplit=1)[0].lower()


def test_this_environment_holds_the_core_and_no_extra():
    reqs = importlib.metadata.requires("prioik") or []
    core = {_requirement_name(r) for r in reqs if "extra ==" not in r}
    assert core == {"numpy", "scipy", "threadpoolctl", "tqdm"}
    assert extras.installed() == []
    for extra, (distributions, _) in extras.EXTRAS.items():
        assert extras.missing_distributions(extra) == distributions, extra


def test_the_core_formulations_are_available_and_the_optional_ones_are_not():
    infos = {f.name: f for f in formulations.available()}
    assert set(CORE) == {"reference", "extended_jacobian", "nullspace", "chiaverini",
                         "unifying", "operational_space", "hierarchical_active_set", "sns",
                         "lexls"}
    for name in CORE:
        if name == "lexls" and not LEXLS_BUILT:
            # built only where lexls's headers are found (PRIOIK_LEXLS_DIR): said so
            assert not infos[name].available
            assert "PRIOIK_LEXLS_DIR" in infos[name].reason, infos[name].reason
            continue
        assert infos[name].available, infos[name].reason
    for name, extra in OPTIONAL.items():
        assert not infos[name].available and infos[name].extra == extra
        assert infos[name].reason.endswith(f"install it with `pip install prioik[{extra}]`")


@pytest.mark.parametrize("seed", range(3))
def test_every_core_formulation_solves_a_compatible_stack(seed):
    """Exact formulations meet every task of a compatible stack; the others (chiaverini,
    unifying: not exact below the first level) still meet the first level."""
    rng = np.random.default_rng(seed)
    stack = compatible(rng, 12, 3)
    mass = random_spd(rng, 12)
    for name in (n for n in CORE if n != "lexls" or LEXLS_BUILT):
        opts = {"mass_matrix": mass} if name in ("unifying", "operational_space") else {}
        sol = formulations.solve(stack, name, **opts)
        assert sol.status != "failed" and np.isfinite(sol.x).all(), (name, sol.diagnostics)
        if formulations.get(name).capabilities.exact:
            assert np.max(sol.residuals) <= 1e-9, (name, sol.residuals)
            assert check_lexicographic(stack, sol.x, tol=1e-8).ok, name
        else:
            assert sol.residuals[0] <= 1e-9, (name, sol.residuals)


@pytest.mark.parametrize("kernel", ["cpp", "lapack"])
def test_extended_jacobian_agrees_with_reference_on_conflicting_stacks(kernel):
    rng = np.random.default_rng(7)
    for _ in range(5):
        stack = conflicting(rng, 10, 4)
        ref = formulations.solve(stack, "reference")
        sol = formulations.solve(stack, "extended_jacobian", kernel=kernel)
        assert sol.status == "optimal"
        assert np.linalg.norm(sol.x - ref.x) <= 1e-8 * max(1.0, np.linalg.norm(ref.x))
    stacks = [conflicting(np.random.default_rng(s), 10, 3) for s in range(4)]
    stacks = [s for s in stacks if formulations.registry.stack_shape(s)
              == formulations.registry.stack_shape(stacks[0])]
    batch = formulations.solve_batch(stacks, "extended_jacobian", kernel=kernel)
    assert batch.batched and batch.statuses == ["optimal"] * len(stacks)
    for s, x in zip(stacks, batch.X, strict=False):
        assert np.allclose(x, formulations.solve(s, "reference").x, rtol=0, atol=1e-8)


def test_hierarchical_active_set_takes_inequality_stacks_in_the_core():
    for seed in range(3):
        stack = with_inequalities(np.random.default_rng(seed), 10, 3)
        sol = formulations.solve(stack, "hierarchical_active_set")
        assert sol.status == "optimal", sol.diagnostics
        assert sol.residuals[0] <= 1e-8   # the first level (a feasible box) is met


@pytest.mark.parametrize("name", sorted(OPTIONAL))
def test_an_optional_formulation_names_its_extra_when_asked_for(name):
    stack = compatible(np.random.default_rng(0), 6, 2)
    hint = f"install it with `pip install prioik[{OPTIONAL[name]}]`"
    with pytest.raises(formulations.FormulationError, match=re.escape(hint)):
        formulations.solve(stack, name)


def test_robots_names_the_robots_extra():
    sys.modules.pop("prioik.robots", None)
    with pytest.raises(extras.MissingExtraError, match=re.escape(
            "prioik.robots needs the `robots` extra (pinocchio not installed); "
            "install it with `pip install prioik[robots]`")):
        importlib.import_module("prioik.robots")
    with pytest.raises(ImportError, match=r"pip install prioik\[robots\]"):
        prioik.robots  # noqa: B018 - the lazy attribute imports it


@pytest.mark.parametrize("extra", sorted(extras.EXTRAS))
def test_every_extra_is_reported_missing_by_name(extra):
    with pytest.raises(extras.MissingExtraError) as info:
        extras.require(extra, what="this part")
    assert info.value.extras == (extra,)
    assert str(info.value).endswith(f"install it with `pip install prioik[{extra}]`")


def test_prioik_list_names_every_unavailable_formulation_with_its_extra():
    res = subprocess.run(CLI + ["list"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    lines = {ln.split()[0]: ln for ln in res.stdout.splitlines() if ln.strip()}
    for name in CORE:
        expect = "yes" if name != "lexls" or LEXLS_BUILT else "no"
        assert lines[name].split()[1] == expect, lines[name]
    for name, extra in OPTIONAL.items():
        assert lines[name].split()[1] == "no"
        assert f"install it with `pip install prioik[{extra}]`" in lines[name]
    assert "QP back-ends: none (qpsolvers is not installed; install it with " \
           "`pip install prioik[qp]`)" in res.stdout


def test_prioik_solve_and_validate_run_on_the_core(tmp_path, capsys):
    assert main(["solve", str(EXAMPLES / "small_4x3.json")]) == 0
    out = capsys.readouterr().out
    assert "status: optimal" in out and "level 2 (posture): residual 0.000e+00" in out
    report = tmp_path / "v.md"
    assert main(["validate", "--n-stacks", "2", "--n-max", "8", "--k-max", "3",
                 "--out", str(report)]) == 0
    text = report.read_text(encoding="utf-8")
    assert "## compatible" in text and "| extended_jacobian |" in text
    assert "## with_inequalities" not in text
    assert re.search(r"inequality families \(with_inequalities, infeasible_inequality, "
                     r"random_inequality\) "
                     r"left out: .*pip install prioik\[cvxpy\]", text)
    # the compiled solvers are the core's own, built at install: `prioik compile` says so
    assert main(["compile"]) == 0
    assert "built when prioik is installed" in capsys.readouterr().out
    assert formulations.solve(load_stack(EXAMPLES / "small_4x3.json"),
                              "extended_jacobian").detail.kernel == "cpp"


@pytest.mark.parametrize("argv, extra", [
    (["solve", str(EXAMPLES / "small_4x3.json"), "-f", "cascaded_qp"], "qp"),
    (["solve", str(EXAMPLES / "small_4x3.json"), "-f", "placo"], "placo"),
    (["validate", "--families", "with_inequalities", "--n-stacks", "1"], "cvxpy"),
    (["fencing", "--duration", "0.01"], "robots,plots"),
    (["bench", "--quick"], "plots"),
])
def test_a_command_needing_a_missing_extra_says_so_in_one_line(argv, extra, tmp_path):
    res = subprocess.run(CLI + argv + (["--out", str(tmp_path / "o")]
                                       if argv[0] in ("fencing", "bench", "validate") else []),
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"prioik {argv[0]}: error: ")
    assert f"with `pip install prioik[{extra}]`" in err
