"""``prioik bench``: time every formulation and back-end on G1 fencing and random stacks.

In one process, per case (a set of stacks, :mod:`prioik.benchmarks.stacks`) and per
variant of the ``bench`` report (:mod:`prioik.benchmarks.variants`: one row per back-end
of formulations that have several, and the rows plugins declare for ``bench``): a few
warm-up solves, then ``--repeats`` (default 200) timed solves cycling over the case's
stacks, each through a solver prepared once per layout (:func:`prioik.prepare`, the
path a control loop runs) — :mod:`.tables`. Then, from the same run, the ratios the
benchmark issues name (:mod:`.ratios`), the batch experiment (:mod:`.batch`), the whole
IK step against PlaCo (:mod:`.ik_step`) and the paper's per-control-step comparison
(:mod:`.control_step`). Outputs in ``--out``: ``results.csv``, ``results.md``,
``choice.md`` (the figures of the decision table of
``docs/how-to/choose-a-formulation.md``, :mod:`.choice`; ``--from-csv CSV`` writes it
from a ``results.csv`` alone, no run), ``summary.json``, ``time_vs_n.png``,
``time_vs_k.png``; ``--doc FILE`` also writes the documentation page (:mod:`.page`,
``templates/benchmarks.md``).

With ``--test-set NAME`` it runs test sets in qpbenchmark's shape instead
(:mod:`prioik.benchmarks.testsets`: success per tolerance profile, shifted geometric
means; ``testsets.csv`` and ``testsets.md`` in ``--out``).

One module per concern: :mod:`.settings` (what a run measures), :mod:`.tables`,
:mod:`.choice`, :mod:`.batch`, :mod:`.control_step`, :mod:`.ik_step`, :mod:`.ratios`,
:mod:`.page`, :mod:`.run` (the whole run) and :mod:`.command` (argument parsing only).
"""

from prioik.benchmarks.results import TimingRow, csv_columns

from .ratios import Ratio, ratios
from .run import run_benchmark
from .settings import LEVELS, SIZES, SUCCESS_TOL, Settings, quick_settings

#: the columns of ``results.csv`` (:class:`~prioik.benchmarks.results.TimingRow`)
CSV_COLUMNS = csv_columns(TimingRow)
#: one row of ``results.csv``
Row = TimingRow

__all__ = ["CSV_COLUMNS", "LEVELS", "Ratio", "Row", "SIZES", "SUCCESS_TOL", "Settings",
           "TimingRow", "quick_settings", "ratios", "run_benchmark"]
