"""The one installed namespace: `import prioik` gives the public API and nothing else
is installed at top level; importing it changes no environment variable."""

import json
import subprocess
import sys

import prioik


def test_public_api_is_reachable_from_prioik():
    for name in ("Task", "TaskStack", "solve", "solve_batch", "check_lexicographic",
                 "hierarchy", "formulations", "robots", "benchmarks", "__version__"):
        assert hasattr(prioik, name), name
    assert prioik.robots.__name__ == "prioik.robots"
    assert prioik.Task is prioik.hierarchy.Task
    assert isinstance(prioik.__version__, str) and prioik.__version__[0].isdigit()


def test_no_top_level_packages_and_no_environment_change(tmp_path):
    code = ("import importlib.util, json, os; before = dict(os.environ); import prioik; "
            "import prioik.formulations, prioik.hierarchy; "
            "print(json.dumps({'changed': sorted(k for k in set(os.environ) | set(before) "
            "if os.environ.get(k) != before.get(k)), "
            "'top': [m for m in ('hierarchy', 'formulations', 'robots', 'benchmarks') "
            "if importlib.util.find_spec(m) is not None]}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, check=True)
    report = json.loads(out.stdout)
    assert report == {"changed": [], "top": []}
