"""Comparisons, validation reports, benchmarks and their ``prioik`` commands.

One concern per module:

* :mod:`.variants` — the rows of every report, derived from the formulation registry
  (one ``Variant`` class, one label syntax ``formulation[tag]``) and the rows declared
  for each formulation in :mod:`.report_rows`;
* :mod:`.stacks` — the stacks the benchmarks time (random families, G1 fencing states);
* :mod:`.timing` — repeats under a time budget, medians and percentiles;
  :mod:`.progress`, :mod:`.machine`;
* :mod:`.results` — the result records (one dataclass per kind of row) and their CSV
  writer and reader;
* :mod:`.report` — pages from the templates of ``templates/`` (package data);
  :mod:`.plots` — every figure;
* :mod:`.scenario_runs` — running a scenario's report (fencing, arm, sweeps) through the
  scenario interface of :mod:`prioik.robots.scenario`; :mod:`.placo_baseline`,
  :mod:`.pink_baseline`, :mod:`.mink_baseline`, :mod:`.external` — the external IK
  libraries (:mod:`.mink_step`: mink's IK step beside prioik's and PlaCo's);
* one module per experiment: :mod:`.bench` (a package), :mod:`.validation`,
  :mod:`.properties`, :mod:`.fencing` (with :mod:`.reproduction`, its page),
  :mod:`.arm`, :mod:`.sweep`, :mod:`.fuzz`, :mod:`.saved_runs`, each declaring its
  ``prioik`` command (``add_parser``), which :mod:`prioik.cli` imports only when that
  command runs (the core commands ``list``, ``solve``, ``compile`` and ``compare`` are
  :mod:`prioik.commands` and :mod:`prioik.compare`).

Importing this package changes nothing in the process: the ``prioik`` command limits
BLAS to one thread itself (:mod:`prioik.threads`, with ``threadpoolctl``),
because every matrix here is small and a multi-threaded BLAS spends more on waking
threads than on arithmetic (measured: ``operational_space`` at n = 35 took 9.7 ms with
threads, 1.1 ms without).
"""
