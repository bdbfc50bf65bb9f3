"""The ``prioik`` command line: list, solve, compare and clean errors (exit 2)."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from prioik.cli import main
from prioik.compare import examples_dir


def test_list_shows_formulations_and_backends(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "extended_jacobian" in out and "reference" in out
    assert "QP back-ends qpsolvers sees here:" in out


def test_solve_prints_x_and_residuals(capsys):
    path = examples_dir() / "small_4x3.json"
    assert main(["solve", str(path), "-f", "extended_jacobian", "-o", "nullspace=svd"]) == 0
    out = capsys.readouterr().out
    assert "status: optimal" in out and "x = [" in out
    assert "level 2 (posture): residual" in out


def test_solve_verify_runs_the_stage_apart_and_prints_its_time(capsys):
    """``--verify certificate`` certifies the answer and prints the stage's time beside
    the solve's; ``--verify none`` prints none; an unknown mode exits 2 naming them."""
    path = str(examples_dir() / "small_4x3.json")
    assert main(["solve", path, "--verify", "certificate"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"status: optimal  time: [\d.]+ µs  verification \(certificate\): "
                     r"[\d.]+ µs", out)
    assert main(["solve", path, "--verify", "none"]) == 0
    assert "verification" not in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        main(["solve", path, "--verify", "nosuch"])
    assert exc.value.code == 2
    assert "lower_point" in capsys.readouterr().err


PEER = Path(__file__).parent / "data" / "peer"


def _level_lines(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith("level ")]


def test_solve_reads_a_lexls_file_and_compares_each_level_with_its_solution(capsys):
    """lexls's test_01 (n 88, 5 levels, its #Solution): each level's ‖w‖² printed beside
    the stored solution's, within 1e-9 of max(1, it) (level 4: 1.588896), the
    certificate passes."""
    assert main(["solve", str(PEER / "lexls_test_01.dat"), "-f", "hierarchical_active_set",
                 "--check"]) == 0
    out = capsys.readouterr().out
    assert "problem: lexls_test_01  (88 unknowns, 5 levels)" in out
    lines = _level_lines(out)
    assert len(lines) == 5
    deltas = [float(re.search(r"\(Δ (\S+) of max\(1, peer\)\)", line).group(1))
              for line in lines]
    assert max(deltas) <= 1e-9, deltas
    assert "peer 1.588896e+00" in lines[4]
    assert "peer: the file's stored solution" in out
    assert "certificate: passes (tol 1e-08;" in out


@pytest.mark.parametrize("name, fmt", [("daqp_hqp4.json", "peer-json"),
                                       ("nipm_t5.json", "peer-json")])
def test_solve_tells_peer_json_from_a_task_stack_file(name, fmt, capsys):
    """A .json file whose levels hold lb/ub is another project's (auto), as --format says
    it; its stated values (DAQP's stored x, NIPM-HLSP's hand-worked f) printed beside."""
    for argv in (["solve", str(PEER / name)], ["solve", str(PEER / name), "--format", fmt]):
        assert main(argv + ["-f", "hierarchical_active_set"]) == 0
        out = capsys.readouterr().out
        deltas = [float(re.search(r"\(Δ (\S+) of", line).group(1))
                  for line in _level_lines(out)]
        assert deltas and max(deltas) <= 1e-9
    assert main(["solve", str(PEER / name), "--format", "stack"]) == 2
    assert "unknown" in capsys.readouterr().err


def test_solve_picks_problems_of_a_soth_file(capsys):
    """soth's new.txt holds three problems; its third is malformed ('equalities 1' with two
    rows): the whole file is refused naming it and the --problems that selects the
    problems that parse; --problems 0,1 solves the first two."""
    path = str(PEER / "soth_new.txt")
    assert main(["solve", path]) == 2
    err = capsys.readouterr().err.strip()
    assert "problem 2, level 2: 'equalities 1' but 2 rows follow" in err
    assert err.endswith("problems 0, 1 parse: read them alone with problems=[0, 1] "
                        "(prioik solve --problems 0,1)")
    assert len(err.splitlines()) == 1
    assert main(["solve", path, "--problems", "0,1", "-f", "hierarchical_active_set",
                 "--check"]) == 0
    out = capsys.readouterr().out
    assert "problem: soth_new#0  (1 unknowns, 3 levels)" in out
    assert "problem: soth_new#1  (3 unknowns, 3 levels)" in out
    assert out.count("certificate: passes") == 2
    for argv, message in (([path, "--problems", "0,7"], "problem 7 requested, the file holds 3"),
                          ([path, "--problems", "a"], "--problems takes comma-separated"),
                          ([str(PEER / "nipm_t5.json"), "--problems", "0"],
                           "--problems picks problems of a soth file")):
        assert main(["solve"] + argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1


def test_solve_check_exits_1_when_the_answer_fails_the_certificate(capsys):
    """The damped extended Jacobian (eq. 27, λ 0.1) on a conflicting stack is not
    lexicographically optimal: --check names the level and exits 1; the exact one 0."""
    path = str(examples_dir() / "small_4x3.json")
    assert main(["solve", path, "-o", "damping=0.1", "--check"]) == 1
    out = capsys.readouterr().out
    assert "certificate: fails at level 1 (reach): KKT residual" in out
    assert main(["solve", path, "--check"]) == 0
    assert "certificate: passes" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["solve", "missing.json"], "cannot read"),
    (["solve", "{small}", "-f", "magic"], "unknown formulation 'magic'"),
    (["solve", "{small}", "-o", "dampnig=1"], "has no option dampnig"),
    (["solve", "{small}", "-o", "novalue"], "--option takes key=value"),
])
def test_bad_input_prints_one_line_and_exits_2(argv, message, capsys):
    argv = [a.replace("{small}", str(examples_dir() / "small_4x3.json")) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_invalid_stack_file_names_the_task(tmp_path, capsys):
    bad = tmp_path / "nan.json"
    bad.write_text(json.dumps({"levels": [{"name": "arm", "A": [[1.0, 2.0]],
                                           "b": [float("nan")]}]}))
    assert main(["solve", str(bad)]) == 2
    assert "task 'arm': b holds NaN" in capsys.readouterr().err


def test_compare_prints_a_table(capsys):
    assert main(["compare", str(examples_dir() / "small_4x3.json"), "--repeats", "2",
                 "--formulations", "reference,extended_jacobian"]) == 0
    out = capsys.readouterr().out
    assert "dist. to ref" in out and "extended_jacobian" in out


def test_console_script_runs():
    exe = [sys.executable, "-m", "prioik.cli", "list"]
    res = subprocess.run(exe, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "reference" in res.stdout


SMALL = str(examples_dir() / "small_4x3.json")


@pytest.mark.parametrize("content, message", [
    (b"\x89PNG\r\n\x1a\n\x00\xff\xfe", "bad.json: not a UTF-8 JSON text file"),
    ('{"levels": [[{"A": [[' + "9" * 400 + ']], "b": [1]}]]}', "bad.json: an integer of 400"),
    ('{"levels": ' + "[" * 100_000 + "]" * 100_000 + "}", "bad.json: JSON nested too deeply"),
    ('{"format": 2, "levels": [[{"A": [[1]], "b": [1]}]]}', "bad.json: unsupported format 2"),
    ('{"extra": 0, "levels": [[{"A": [[1]], "b": [1]}]]}', "bad.json: unknown top-level keys"),
])
def test_bad_files_print_one_line_naming_the_file_and_exit_2(tmp_path, capsys, content,
                                                             message):
    bad = tmp_path / "bad.json"
    (bad.write_bytes if isinstance(content, bytes) else bad.write_text)(content)
    assert main(["solve", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


def test_compare_refuses_an_unknown_formulation(capsys):
    assert main(["compare", SMALL, "--formulations", "foo", "--repeats", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown formulation 'foo'" in err and len(err.splitlines()) == 1


def test_closed_pipe_exits_quietly():
    # `prioik solve FILE | head -0`: the reader leaves before the output is written
    exe = [sys.executable, "-m", "prioik.cli", "solve", SMALL]
    proc = subprocess.Popen(exe, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()          # closed before the first write: every write fails
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0
    assert "Broken pipe" not in err and "Error" not in err, err


def test_compile_says_there_is_nothing_to_compile_and_checks_names(capsys):
    from prioik.formulations.registry import NOTHING_TO_COMPILE
    assert main(["compile"]) == 0
    assert capsys.readouterr().out.splitlines() == [NOTHING_TO_COMPILE]
    assert main(["compile", "--formulations", "extended_jacobian,reference"]) == 0
    assert capsys.readouterr().out.splitlines() == [NOTHING_TO_COMPILE]
    assert main(["compile", "--formulations", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope" in err and len(err.splitlines()) == 1


def test_compile_help_says_the_core_is_built_at_install(capsys):
    with pytest.raises(SystemExit):
        main(["compile", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "built when prioik is installed" in out and "numba" not in out


@pytest.mark.parametrize("command", ["fencing", "arm"])
def test_turn_steps_must_be_a_non_negative_integer(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--turn-steps", "-1"])
    assert exc.value.code == 2
    assert "--turn-steps: invalid non-negative integer value: '-1'" in capsys.readouterr().err


def _nothing_may_run(monkeypatch):
    """Every command's work made to fail the test: an unknown name must exit before."""
    def ran(*args, **kwargs):
        raise AssertionError("the command ran before refusing an unknown name")
    from prioik import compare
    from prioik.benchmarks import fuzz, scenario_runs, validation
    from prioik.benchmarks.bench import run as bench_run
    monkeypatch.setattr(validation, "run_family", ran)
    monkeypatch.setattr(validation, "report", ran)
    monkeypatch.setattr(bench_run, "run_benchmark", ran)
    monkeypatch.setattr(scenario_runs, "run_scenario", ran)
    monkeypatch.setattr(fuzz, "run", ran)
    monkeypatch.setattr(compare, "compare_stack", ran)


@pytest.mark.parametrize("argv, message, known", [
    (["validate", "--formulations", "nosuch"], "unknown formulation 'nosuch'; known: ",
     "extended_jacobian"),
    (["validate", "--formulations", "reference,nosuch[x]"],
     "unknown formulation 'nosuch[x]'; known: ", "hierarchical_active_set"),
    (["validate", "--families", "nosuch"], "unknown families ['nosuch']; known: ",
     "conflicting"),
    (["bench", "--formulations", "nosuch"], "unknown formulation 'nosuch'; known: ",
     "extended_jacobian"),
    (["bench", "--family", "nosuch"], "unknown family 'nosuch'; known: ", "conflicting"),
    (["fuzz", "--paths", "nosuch"], "unknown fuzz path 'nosuch'; known: ", "ej_qr_cpp"),
    (["fencing", "--formulations", "nosuch"], "unknown run(s) nosuch; known: ",
     "extended_jacobian"),
    (["compare", "--formulations", "nosuch"], "unknown formulation 'nosuch'; known: ",
     "extended_jacobian"),
])
def test_an_unknown_name_exits_2_at_once_with_the_valid_ones(argv, message, known, tmp_path,
                                                            monkeypatch, capsys):
    """prioik validate --formulations nosuch used to run every family and exit 0."""
    _nothing_may_run(monkeypatch)
    out = tmp_path / "out"
    extra = {"validate": ["--out", str(out / "v.md")], "bench": ["--out", str(out)],
             "fencing": ["--out", str(out)], "fuzz": ["--out", str(out)]}
    assert main(argv + extra.get(argv[0], [])) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and known in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_an_unknown_row_label_of_a_known_formulation_lists_the_labels(tmp_path, monkeypatch,
                                                                      capsys):
    from prioik.benchmarks import validation
    monkeypatch.setattr(validation, "run_family", lambda *a, **k: pytest.fail("ran"))
    out = tmp_path / "v.md"
    for argv in (["validate", "--out", str(out)], ["bench", "--out", str(tmp_path / "b")]):
        assert main(argv + ["--formulations", "extended_jacobian[nosuch]"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"prioik {argv[0]}: error: unknown formulation or row label "
                              "'extended_jacobian[nosuch]'; known formulations: reference, ")
        assert "; row labels: " in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_every_library_error_is_one_line_and_exit_2(monkeypatch, capsys):
    """An UnknownNameError (a KeyError) raised under a command is reported as the
    others are, not as a traceback."""
    from prioik import commands
    from prioik.errors import UnknownNameError

    def unknown(*args, **kwargs):
        raise UnknownNameError("model 'x' has no frame 'tip'")
    monkeypatch.setattr(commands, "_problems", unknown)
    assert main(["solve", SMALL]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "prioik solve: error: model 'x' has no frame 'tip'"


@pytest.mark.parametrize("argv", [["list"], ["solve", SMALL], ["compile"],
                                  ["compare", SMALL, "--repeats", "1",
                                   "--formulations", "reference"]])
def test_core_commands_import_nothing_of_the_benchmarks(argv):
    """``list``, ``solve``, ``compile`` and ``compare`` are the library's own commands
    (prioik.cli, prioik.commands, prioik.compare): running one imports no module of
    prioik.benchmarks."""
    code = ("import sys; from prioik.cli import main; code = main(sys.argv[1:]); "
            "print([m for m in sys.modules if m.startswith('prioik.benchmarks')]); "
            "sys.exit(code)")
    res = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == "[]"


def test_a_benchmark_command_is_dispatched_to_its_module_alone():
    from prioik import cli
    assert cli.COMMANDS["fencing"] == "prioik.benchmarks.fencing"
    parser = cli.build_parser("fencing")
    choices = parser._subparsers._group_actions[0].choices     # the commands it declares
    assert list(choices) == ["fencing"]
    full = cli.build_parser()._subparsers._group_actions[0].choices
    assert list(full) == list(cli.COMMANDS)       # every command, in COMMANDS' order


@pytest.mark.parametrize("command", [None, "list", "solve", "fencing", "replay", "bench"])
def test_help_is_the_same_whichever_parser_is_built(command, capsys):
    """A command's ``--help`` from its one-module parser equals the whole parser's."""
    from prioik import cli
    argv = [command, "--help"] if command else ["--help"]
    outs = []
    for parser in (cli.build_parser(), cli.build_parser(command)):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 0
        outs.append(capsys.readouterr().out)
    assert outs[0] == outs[1] and "usage: prioik" in outs[0]


def test_a_refused_command_line_prints_the_whole_usage(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["list", "--no-such-option"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "{list,solve,compile,fencing," in err
    assert "unrecognized arguments: --no-such-option" in err
