"""``prioik sweep``: randomized and gridded scenario sweeps on ``dask.distributed``.

One module per concern:

* :mod:`.config` — the declared sweep (TOML or JSON): scenario parameters as fixed
  values, grid axes or random ranges × formulation variants; validated once, expanded
  into a :class:`~.config.Plan` of independent runs;
* :mod:`.scenarios` — per scenario: its parameters, how a point becomes a built
  scenario (target from a reach margin, gains, step, timing), the success criteria;
* :mod:`.task` — one run → one summary row (what a worker executes);
* :mod:`.store` — the rows file (CSV, one row appended and flushed per finished run)
  and resuming from it;
* :mod:`.execute` — running the plan: in-process, on an embedded ``LocalCluster`` or on
  an existing scheduler; progress with counts and ETA;
* :mod:`.stats`, :mod:`.plots`, :mod:`.report` — success rates with Wilson intervals,
  figures, the markdown page (``templates/report.md``);
* :mod:`.command` — argument parsing only.
"""

from .config import Plan, SweepConfigError, load_config, plan_from_config
from .execute import SweepOutcome, run_sweep

__all__ = ["Plan", "SweepConfigError", "SweepOutcome", "load_config", "plan_from_config",
           "run_sweep"]
