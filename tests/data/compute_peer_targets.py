"""Compute which peer cases have trusted per-level ‖w_i‖² targets; writes peer_targets.json.

Run from the repository root: ``.venv/bin/python tests/data/compute_peer_targets.py``.

A case's targets are trusted when

* ``peer``: the peer stores or asserts a solution and it passes the lexicographic
  certificate (``check_lexicographic``, levels, ``DEFAULT_CERTIFICATE_TOL``): the targets
  are its ``‖w_i‖²``;
* ``computed``: otherwise, when at least two independent prioik answers (QP back-ends
  of ``cascaded_qp`` and ``cvxpy``) pass the certificate and agree on every ``‖w_i‖²``
  within ``1e-9 · max(1, ‖w_i‖²)``: the targets are the first one's.

A peer's own hand-worked values (NIPM-HLSP's ``f_analytic``) are compared with the
targets (``analytic_agrees``) but never trusted alone. Cases that meet neither rule are
recorded with the reason.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from prioik import formulations
from prioik.hierarchy import check_lexicographic, lexicographic_residuals, load_peer, load_soth

HERE = Path(__file__).parent / "peer"
OUT = Path(__file__).parent / "peer_targets.json"
AGREE = 1e-9
SOLVERS = (("cascaded_qp", {"solver": "quadprog"}), ("cascaded_qp", {"solver": "proxqp"}),
           ("cascaded_qp", {"solver": "clarabel", "tolerance": 1e-12}),
           ("cascaded_qp", {"solver": "daqp"}), ("cvxpy", {}))


def problems():
    out = []
    for path in sorted(HERE.iterdir()):
        if path.suffix not in (".dat", ".txt", ".json"):
            continue
        out += load_soth(path, problems=[0, 1]) if path.name == "soth_new.txt" else load_peer(path)
    return out


def label(name, opts):
    return name + (f"[{opts['solver']}]" if "solver" in opts else "")


def record(p) -> dict:
    s = p.stack
    rec: dict = {"n": s.n, "levels": len(s)}
    if p.x_stored is not None and check_lexicographic(s, p.x_stored).ok:
        rec.update(trust="peer", targets=(lexicographic_residuals(s, p.x_stored) ** 2).tolist())
    else:
        if p.x_stored is not None:
            rec["peer_x_fails_certificate"] = True
        good = []
        for name, opts in SOLVERS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = formulations.solve(s, name, **opts, certify=False)
            if sol.ok and check_lexicographic(s, sol.x).ok:
                good.append((label(name, opts), lexicographic_residuals(s, sol.x) ** 2))
        agreeing = [good[0]] if good else []
        for lab, w in good[1:]:
            if np.all(np.abs(w - good[0][1]) <= AGREE * np.maximum(1.0, good[0][1])):
                agreeing.append((lab, w))
        if len(agreeing) >= 2:
            rec.update(trust="computed", targets=agreeing[0][1].tolist(),
                       solvers=[lab for lab, _ in agreeing])
        else:
            rec.update(trust=None, certified=[lab for lab, _ in good],
                       reason="fewer than two certified answers agree within 1e-9")
    if p.level_targets is not None:
        rec["analytic"] = p.level_targets.tolist()
        if rec.get("targets") is not None:
            t = np.array(rec["targets"])
            rec["analytic_agrees"] = bool(np.all(np.abs(p.level_targets - t)
                                                 <= AGREE * np.maximum(1.0, t)))
    return rec


def main() -> None:
    out = {p.name: record(p) for p in problems()}
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    for name, rec in out.items():
        print(f"{name:22s} {rec['trust']!s:9s} {rec.get('solvers', rec.get('reason', ''))}")


if __name__ == "__main__":
    main()
