// The equality-first try's views (private).
#pragma once

#include "active_set_internal.hpp"

namespace prioik::detail {

/// The equality-first try's parts: the weighed equality (and held) rows eB and their
/// targets ec, the nested QR's per-level vectors and its workspace (qr: its reflectors
/// V, beta, pos and rotated unknowns y are read after it), the row maps, and the scratch
/// it shares with the active set (L, fs: 4 rows of R).
struct EqFirst {
    Mat eB, V, Lmat;
    double* eflat;
    double *ec, *scales, *mu2, *emargins, *step_bound;
    index *estarts, *eranks, *ucol, *erow, *rowperm, *prow, *pside, *pinned, *hcol, *ecol;
    /// per QR row, the column of its one non-zero entry when the row was built on one
    /// (NestedQRParameters::row_columns), else −1
    index* qcol;
    double* fs;
    double* work;      // the fixed columns' test's scratch (≥ 2 n + M)
    NestedQRWorkspace* qr;
    double *beta, *y;
    index* pos;
    index* ispare;
    double* Lflat;
    // the held rows: as fixed coordinates (fixed) or as equalities; their count and the
    // lowest level holding one; the free coordinates' count n2 and the QR's rows m
    bool fixed = false;
    index nheld = 0, last_held = -1, n2 = 0, m = 0;

    EqFirst(Ctx& c, ActiveSetWorkspace& ws);
};

double add_level_gradient(const Ctx& c, const EqFirst& e, index s0, index s1, const double* x,
                          double* g);
index held_rows_optimal(const Ctx& c, EqFirst& e, const double* x);
index fixed_columns_optimal(const Ctx& c, EqFirst& e, const double* x);

}  // namespace prioik::detail
