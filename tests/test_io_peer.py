"""Loaders of the peers' hierarchy formats (lexls .dat, soth .txt, peer JSON)."""

from pathlib import Path

import numpy as np
import pytest

from prioik.hierarchy import (
    TaskStackError,
    lexicographic_residuals,
    load_lexls,
    load_peer,
    load_peer_json,
    load_soth,
)

PEER = Path(__file__).parent / "data" / "peer"


def test_lexls_test_01_reads_as_lexls_does():
    p = load_lexls(PEER / "lexls_test_01.dat")
    s = p.stack
    assert s.n == 88 and len(s) == 5
    assert [lv.m for lv in s] == [74, 33, 3, 2, 97]
    # simple bounds, 1-based: "85 0 0 3" is x[84] == 0, "88 0.19 0.3 1" bounds x[87]
    eq, ineq = s[0]
    assert eq.name == "L0_eq" and eq.is_equality and eq.m == 2
    np.testing.assert_array_equal(np.flatnonzero(eq.A[0]), [84])
    np.testing.assert_array_equal(eq.b, [0.0, -0.095])
    lo, up = ineq.bounds()
    row = np.flatnonzero(ineq.A[:, 87])
    assert row.size == 1 and lo[row[0]] == 0.19 and up[row[0]] == 0.3
    assert p.x_stored.shape == (88,) and p.x_stored[-1] == 0.19
    assert p.extras["solution_guess"].shape == (88,)
    assert p.extras["active_set_guess"][0][:3] == [3, 3, 0]
    # lexls's stored solution: levels 0-3 met, level 4 ‖w‖² = 1.58890 (peer README)
    w2 = lexicographic_residuals(s, p.x_stored) ** 2
    assert np.all(w2[:4] < 1e-20)
    assert w2[4] == pytest.approx(1.58890, abs=1e-5)


def test_lexls_simple_bound_index_is_one_based():
    """Read 0-based, the stored solution would violate its own bounds (0.19 on x[87])."""
    p = load_lexls(PEER / "lexls_test_01.dat")
    ineq = p.stack[0][1]
    shifted = np.roll(ineq.A, 1, axis=1)
    lo, up = ineq.bounds()
    Ax = shifted @ p.x_stored
    assert np.linalg.norm(np.maximum(lo - Ax, 0) + np.maximum(Ax - up, 0)) > 0.1
    Ax = ineq.A @ p.x_stored
    assert np.linalg.norm(np.maximum(lo - Ax, 0) + np.maximum(Ax - up, 0)) < 1e-12


def _lexls(tmp_path, body, header="#HierType\n200\n#nVar\n2\n#nObj\n2\n#nCtr\n1 1\n"
           "#ObjType\n100 200\n"):
    f = tmp_path / "h.dat"
    f.write_text(header + body)
    return f


def test_lexls_small_file_and_errors(tmp_path):
    f = _lexls(tmp_path, "#OBJECTIVE 0\n2 -1 1\n#OBJECTIVE 1\n1 1 3 3\n#Solution\n3\n0\n")
    p = load_lexls(f)
    np.testing.assert_array_equal(p.stack[0][0].A, [[0.0, 1.0]])
    assert p.stack[1][0].is_equality and p.stack[1][0].b[0] == 3.0
    np.testing.assert_array_equal(p.x_stored, [3.0, 0.0])
    with pytest.raises(TaskStackError, match=r"h.dat: level 0, row 0: simple-bound index 0 "
                                             r"is not in 1..2 \(1-based\)"):
        load_lexls(_lexls(tmp_path, "#OBJECTIVE 0\n0 -1 1\n#OBJECTIVE 1\n1 1 3 3\n"))
    with pytest.raises(TaskStackError, match=r"level 1, row 0: 3 numbers, 4 expected"):
        load_lexls(_lexls(tmp_path, "#OBJECTIVE 0\n1 -1 1\n#OBJECTIVE 1\n1 1 3\n"))
    with pytest.raises(TaskStackError, match=r"missing header field\(s\) #nCtr"):
        load_lexls(_lexls(tmp_path, "", header="#HierType\n200\n#nVar\n2\n#nObj\n1\n"
                                               "#ObjType\n200\n"))
    with pytest.raises(TaskStackError, match=r"level 1: simple bounds \(type 100\) are only"):
        load_lexls(_lexls(tmp_path, "#OBJECTIVE 0\n1 -1 1\n#OBJECTIVE 1\n1 1 3\n",
                          header="#HierType\n200\n#nVar\n2\n#nObj\n2\n#nCtr\n1 1\n"
                                 "#ObjType\n100 100\n"))
    with pytest.raises(TaskStackError, match=r"level 1, task 'L1_ineq': lower > upper"):
        load_lexls(_lexls(tmp_path, "#OBJECTIVE 0\n1 -1 1\n#OBJECTIVE 1\n1 1 3 2\n"))
    with pytest.raises(TaskStackError, match="cannot read"):
        load_lexls(tmp_path / "missing.dat")


def test_soth_sot_is_hrp2_shaped_with_unbounded_sides():
    (p,) = load_soth(PEER / "soth_sot.txt")
    s = p.stack
    assert s.n == 30 and len(s) == 5 and p.x_stored is None
    box = s[0]
    assert box.names == ("L0_ineq",) and box.m == 30
    np.testing.assert_array_equal(box[0].A[:, :30], np.eye(30))
    (plus,) = load_soth(PEER / "soth_plus.txt")
    lo, up = plus.stack[1][0].bounds()       # "1 3 0   3 3e25": x0 + 3 x1 ≥ 3
    np.testing.assert_array_equal(lo, [3.0, 4.0])
    assert np.isposinf(up).all()
    lo, up = plus.stack[0][0].bounds()       # "-1e25 1": upper only
    assert np.isneginf(lo).all() and up.tolist() == [1.0, 2.0]
    (minus,) = load_soth(PEER / "soth_minus.txt")
    assert minus.stack[0].names == ("L0_eq", "L0_ineq")


def test_soth_file_with_several_problems():
    first, second = load_soth(PEER / "soth_new.txt", problems=[0, 1])
    assert first.name == "soth_new#0" and first.stack.n == 1 and len(first.stack) == 3
    assert second.stack.n == 3 and [lv.m for lv in second.stack] == [1, 2, 2]
    # the third problem says "equalities 1" and gives two rows (soth's reader would
    # misread it): refused, naming it
    with pytest.raises(TaskStackError, match=r"soth_new.txt: problem 2, level 2: "
                                             r"'equalities 1' but 2 rows follow; problems "
                                             r"0, 1 parse: read them alone with "
                                             r"problems=\[0, 1\]") as err:
        load_soth(PEER / "soth_new.txt")
    assert (err.value.detail["failed"], err.value.detail["parsed"]) == ([2], [0, 1])
    with pytest.raises(TaskStackError, match=r"problem 2, level 2: .* rows follow$"):
        load_soth(PEER / "soth_new.txt", problems=[2])      # nothing else asked: no hint
    with pytest.raises(TaskStackError, match="problem 5 requested, the file holds 3"):
        load_soth(PEER / "soth_new.txt", problems=[5])


def test_soth_errors(tmp_path):
    f = tmp_path / "p.txt"
    f.write_text("variable size 2\nlevel\nequalities 1\n1 0\ninequalities 0\nend\n")
    with pytest.raises(TaskStackError, match=r"p.txt: problem 0, level 0, equalities row 0: "
                                             r"2 numbers, 3 expected"):
        load_soth(f)
    f.write_text("variable size 2\nlevel\ninequalities 0\nend\n")
    with pytest.raises(TaskStackError, match="'equalities m' expected"):
        load_soth(f)


def test_peer_json_drops_empty_levels_and_splits_equalities():
    p = load_peer_json(PEER / "nipm_t11.json")      # level 0 empty
    assert p.source_levels == (1,) and len(p.stack) == 1
    np.testing.assert_array_equal(p.level_targets, [0.0])
    p = load_peer_json(PEER / "nipm_t4.json")       # x0 = 1 and -x0 ≥ -1 on one level
    assert p.stack[0].names == ("L0_eq", "L0_ineq")
    np.testing.assert_array_equal(p.stack[0][0].b, [1.0])
    np.testing.assert_array_equal(p.extras["x_analytic"], [1.0])
    p = load_peer_json(PEER / "daqp_hqp4.json")
    np.testing.assert_array_equal(p.x_stored, [1.0, 0.5, -1.0])
    assert "darnstrom/daqp" in p.source
    lo, up = p.stack[1][0].bounds()
    assert np.isneginf(lo[0]) and up[0] == 1.0


def test_peer_json_errors(tmp_path):
    f = tmp_path / "bad.json"
    f.write_text('{"n": 2, "levels": [{"A": [[1, 0]], "lb": [0]}]}')
    with pytest.raises(TaskStackError, match="bad.json: level 0 needs 'A', 'lb' and 'ub'"):
        load_peer_json(f)
    f.write_text('{"n": 2, "levels": [{"A": [[1, 0]], "lb": [0, 1], "ub": [1, 2]}]}')
    with pytest.raises(TaskStackError, match="level 0 has 1 rows but 2 lower"):
        load_peer_json(f)
    f.write_text('{"n": 2, "levels": [{"A": [[1, 0]], "lb": [0], "ub": [1]}], '
                 '"x_stored": [1]}')
    with pytest.raises(TaskStackError, match="'x_stored' has 1 entries, 2 expected"):
        load_peer_json(f)


@pytest.mark.parametrize("path", sorted(p for p in PEER.iterdir()
                                        if p.suffix in (".dat", ".txt", ".json")),
                         ids=lambda p: p.name)
def test_every_peer_file_loads(path):
    problems = load_peer(path) if path.name != "soth_new.txt" \
        else load_soth(path, problems=[0, 1])
    for p in problems:
        assert p.stack.n >= 1 and len(p.stack) == len(p.source_levels) >= 1
        if p.x_stored is not None:
            assert p.x_stored.shape == (p.stack.n,)
        if p.level_targets is not None:
            assert p.level_targets.shape == (len(p.stack),)
