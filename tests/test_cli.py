"""The ``prioik`` command line: list, solve, compare and clean errors (exit 2)."""

import json
import subprocess
import sys

import pytest

from prioik.benchmarks.cli import main
from prioik.benchmarks.compare import examples_dir


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
    bad.write_text(json.dumps({"levels": [{"name": "arm", "A": [[1.0, 2.0]], "b": [float("nan")]}]}))
    assert main(["solve", str(bad)]) == 2
    assert "task 'arm': b holds NaN" in capsys.readouterr().err


def test_compare_prints_a_table(capsys):
    assert main(["compare", str(examples_dir() / "small_4x3.json"), "--repeats", "2",
                 "--formulations", "reference,extended_jacobian"]) == 0
    out = capsys.readouterr().out
    assert "dist. to ref" in out and "extended_jacobian" in out


def test_console_script_runs():
    exe = [sys.executable, "-m", "prioik.benchmarks.cli", "list"]
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
    exe = [sys.executable, "-m", "prioik.benchmarks.cli", "solve", SMALL]
    proc = subprocess.Popen(exe, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()          # closed before the first write: every write fails
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0
    assert "Broken pipe" not in err and "Error" not in err, err


def test_compile_prints_each_compiled_formulation_and_refuses_others(capsys):
    assert main(["compile"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in ("extended_jacobian", "hierarchical_active_set"):
        assert f"{name}: compiling or loading its kernels ..." in lines
        assert any(line.startswith(f"{name}: done in ") for line in lines)
    assert len(lines) == 4
    assert main(["compile", "--formulations", "reference"]) == 2
    err = capsys.readouterr().err.strip()
    assert "'reference' has no compiled kernels" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("command", ["fencing", "arm"])
def test_turn_steps_must_be_a_non_negative_integer(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--turn-steps", "-1"])
    assert exc.value.code == 2
    assert "--turn-steps: invalid non-negative integer value: '-1'" in capsys.readouterr().err
