#include "prioik/flops.hpp"

namespace prioik {

namespace {

inline double f(Index v) { return static_cast<double>(v); }

// Householder QR of `rows` × r held transposed with a right-hand side (reflect_column per
// column, its norm first): per column j, w = rows - j entries
double householder_columns_flops(Index rows, Index r) {
  double flops = 0.0;
  for (Index j = 0; j < r; ++j) {
    const double w = f(rows - j);
    flops += 2.0 * w + 5.0 + f(r - j - 1) * (4.0 * w + 2.0) + 4.0 * w + 2.0;
  }
  return flops;
}

}  // namespace

double small_least_squares_flops(Index m, Index r, bool damped) {
  const Index rows = damped ? m + r : m;
  double flops = (damped ? 1.0 : 0.0) + householder_columns_flops(rows, r) + f(r * r);
  if (!damped) flops += 4.0 * f(m * r) + 2.0 * f(r * r) + f(r);   // the refinement
  return flops;
}

double full_rank_least_squares_flops(Index m, Index d) {
  // column norms, the pivoted QR (with the norms downdated: 2 per later column), back
  // substitution, the residual, Kᵀ r and the corrected semi-normal step
  double flops = 2.0 * f(m * d) + householder_columns_flops(m, d) + f(d * (d - 1));
  flops += f(d * d) + 4.0 * f(m * d) + 2.0 * f(d * d) + f(d);
  return flops;
}

double pivoted_lq_level_flops(Index m, Index n, Index col, Index r, Index below) {
  const Index d = n - col;
  double flops = f(m) * (2.0 * f(col) + 1.0 + 2.0 * f(d));     // rhs and row norms
  for (Index j = 0; j < r; ++j) {
    const double w = f(d - j);
    flops += 2.0 * w + 1.0;                         // the pivot's exact norm
    flops += 2.0 * w + 1.0;                         // the reflector
    flops += f(m - j - 1 + below) * (4.0 * w + 1.0);  // applied to the rows after it
    flops += 2.0 * f(m - j - 1);                    // the level's norms downdated
  }
  if (r < m && r < d) flops += 2.0 * f(d - r) + 1.0;    // the rejected pivot's norm
  return flops;
}

double reflectors_flops(const Index* pos, Index count, Index n) {
  double flops = 0.0;
  for (Index t = 0; t < count; ++t) flops += 4.0 * f(n - pos[t]) + 1.0;
  return flops;
}

double unit_rows_flops(Index m, Index n, Index col, const Index* pos, Index count) {
  const Index nu = n - m, d = n - col;
  double flops = 4.0 * f(m);                                // g = Sᵀ c / s²
  flops += f(nu + 1) * reflectors_flops(pos, count, n);      // free directions and Qᵀ g
  if (col > 0) flops += f(nu) * (2.0 * f(col) + 2.0 * f(d));   // the fixed part
  flops += f(nu * (nu + 1) / 2) * (2.0 * f(d) + 1.0) + f(nu);   // G = I - Z_U Z_Uᵀ
  flops += 2.0 * (f(nu * nu * nu) / 3.0 + f(nu * nu));          // two Cholesky factors
  flops += 4.0 * f(nu * d) + 2.0 * f(nu * nu);                  // the Woodbury step
  return flops;
}

}  // namespace prioik
