"""The reproduction page's like-for-like section (prioik.benchmarks.reproduction),
generated from a synthetic measurement: the table's ratios and the reading that says
which differences are the formulations' and which the implementation's."""

from prioik.benchmarks.like_for_like import BASE
from prioik.benchmarks.report import Page
from prioik.benchmarks.reproduction import like_for_like_section


def _m(seconds, flops, compiled=True):
    return {"compiled": compiled, "median_solve_s": seconds, "flops": flops,
            "statuses": {"optimal": 4}, "solves": 8}


#: EJ 10 µs / 1e4 flops; nullspace 30 µs / 6e4 (rate 2); operational_space 80 µs / 4e4
#: (rate 0.5); unifying 20 µs / 5e4 (rate 2.5); sns numpy
LFL = {"stacks": 4, "n": 35, "repeats": 2, "variants": ["compatible", "incompatible"],
       "measured": {BASE: _m(10e-6, 1e4), "nullspace": _m(30e-6, 6e4),
                    "operational_space": _m(80e-6, 4e4), "unifying": _m(20e-6, 5e4),
                    "sns": _m(500e-6, None, compiled=False)}}


def _rows(text):
    return {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in text.splitlines() if line.startswith("| `")}


def test_like_for_like_table_sets_the_papers_ratios_beside_the_measured_ones():
    text = like_for_like_section(Page("reproduction.md"), LFL)
    rows = _rows(text)
    assert list(rows) == [f"`{BASE}`", "`nullspace`", "`operational_space`", "`unifying`",
                          "`sns`"]
    # paper ratio, kernel, median solve, time ratio, flops, flop ratio, rate
    assert rows["`nullspace`"][1:] == ["1.93", "C++", "30.0 µs", "3.00", "6e+04", "6.00",
                                       "2.00"]
    assert rows["`operational_space`"][1:] == ["3.43", "C++", "80.0 µs", "8.00", "4e+04",
                                               "4.00", "0.50"]
    assert rows["`sns`"][1:] == ["—", "numpy", "500.0 µs", "— (numpy)", "—", "—", "—"]
    assert "2 states of each of the compatible and incompatible runs" in text
    # the reading: flops are the formulations', rates the implementation's
    assert "`nullspace` does 6.00×, `operational_space` does 4.00×, `unifying` does 5.00×" \
        in text
    assert ("flop ratio / time ratio): `nullspace` 2.00, `operational_space` 0.50, "
            "`unifying` 2.50.") in text
    assert "Above 1 (`nullspace`, `unifying`), the time ratio is below" in text
    assert "Below 1 (`operational_space`), the time ratio exceeds" in text
    assert "its solve takes 10.0 µs here" in text
    # against the paper: 1.93, 3.43, 2.29 all below the flop ratios 6, 4, 5; by flops
    # operational_space (4) < unifying (5) < nullspace (6), not the paper's order
    assert "are all below the flop ratios here (6.00, 4.00, 5.00)" in text
    assert ("Ranked by flops the paper's formulations come in another order than the "
            "paper's: `operational_space` < `unifying` < `nullspace` (paper: `nullspace` "
            "< `unifying` < `operational_space`)") in text
    assert "ranked by compiled time, in another order" in text
    assert "out of the ratio columns: `sns` (500 µs)" in text


def test_like_for_like_reading_follows_the_data():
    """All rates above 1, the paper's order kept: no 'Below 1' sentence, 'in the
    paper's order'; without a measurement, no section."""
    lfl = {**LFL, "measured": {BASE: _m(10e-6, 1e4), "nullspace": _m(20e-6, 3e4),
                               "unifying": _m(30e-6, 5e4)}}
    text = like_for_like_section(Page("reproduction.md"), lfl)
    assert "Below 1" not in text and "Above 1 (`nullspace`, `unifying`)" in text
    assert "come in the paper's order; ranked by compiled time, in the paper's order" in text
    assert "Not compiled here" not in text
    assert like_for_like_section(Page("reproduction.md"), None) == ""
    assert like_for_like_section(Page("reproduction.md"), {"measured": {}}) == ""
