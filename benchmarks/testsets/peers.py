"""The peers' hierarchies: the test problems of lexls, soth, DAQP,
Weighted-Hierarchical-QP and NIPM-HLSP kept in ``tests/data/peer``
(:func:`prioik.hierarchy.load_peer`; see that folder's README for their sources).

Each problem carries what its source states: the solution a peer stores or its test
asserts (``x_stored``, and the per-level ``‖w_i‖²`` at it), else NIPM-HLSP's hand-worked
per-level values, else the trusted per-level targets of ``tests/data/peer_targets.json``
(its ``trust``: ``peer`` or ``computed``, agreed by independent QP back-ends). Not
sequential.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from prioik.hierarchy import level_residuals, load_peer, load_soth

from .base import Problem, TestSet

__all__ = ["Peers", "PEER_DIR"]

#: where the peers' files are (the repository's tests/data/peer)
PEER_DIR = Path(__file__).resolve().parents[2] / "tests" / "data" / "peer"


class Peers(TestSet):
    name = "peers"
    description = ("the peers' test hierarchies (lexls, soth, DAQP, Weighted-Hierarchical-"
                   "QP, NIPM-HLSP) with their stated solutions")

    def __init__(self, folder: str | Path = PEER_DIR) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise FileNotFoundError(f"no peer folder at {self.folder} (the repository's "
                                    "tests/data/peer)")

    def problems(self) -> Iterator[Problem]:
        targets_file = self.folder.parent / "peer_targets.json"
        trusted = json.loads(targets_file.read_text()) if targets_file.is_file() else {}
        for path in sorted(self.folder.iterdir()):
            if path.suffix not in (".dat", ".txt", ".json"):
                continue
            # soth_new.txt's third problem declares one row and gives two: the first two
            probs = (load_soth(path, problems=[0, 1]) if path.name == "soth_new.txt"
                     else load_peer(path))
            for p in probs:
                yield _problem(p, trusted.get(p.name))


def _problem(p, trusted: dict | None) -> Problem:
    if p.x_stored is not None:
        x = np.asarray(p.x_stored, dtype=float)
        values = level_residuals(p.stack.data, x) ** 2
        return Problem(p.name, p.stack, solution=x, level_values=values,
                       stated_by="the peer's solution")
    if p.level_targets is not None and all(v is not None for v in p.level_targets):
        return Problem(p.name, p.stack, level_values=np.asarray(p.level_targets, float),
                       stated_by="hand-worked values (NIPM-HLSP)")
    if trusted is not None:
        return Problem(p.name, p.stack, level_values=np.asarray(trusted["targets"], float),
                       stated_by=f"peer_targets.json ({trusted['trust']})")
    return Problem(p.name, p.stack)
