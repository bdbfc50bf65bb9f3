// The linear-algebra steps of the nested pivoted QR, shared by the extended Jacobian and
// the active set: Householder reflectors (built, applied, accumulated), a column-pivoted
// QR of a level with full column rank, a small (damped) least squares, a Cholesky
// factorization, and the unit-rows step (free directions, Woodbury).
//
// Every function works on memory its caller owns (a prepared solver's workspace) and
// allocates nothing. Matrices are row-major views (MatrixRef); a matrix "held
// transposed" keeps its column j in row j, so that the inner loops run over contiguous
// memory. Each loop does its operations in the order it is written (the sums of dot() in
// eight written-out partial sums, then four); the arithmetic is IEEE double as written
// (no fast math, no fused multiply-add: core/CMakeLists.txt).
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

namespace prioik {

using Index = std::ptrdiff_t;

constexpr double kInf = std::numeric_limits<double>::infinity();

// A row-major view of rows × cols doubles, row i at data + i * stride.
struct MatrixRef {
  double* data = nullptr;
  Index rows = 0;
  Index cols = 0;
  Index stride = 0;

  double* row(Index i) const { return data + i * stride; }
  double& operator()(Index i, Index j) const { return data[i * stride + j]; }
  // rows [first, first + count) of this view
  MatrixRef middle_rows(Index first, Index count) const {
    return MatrixRef{data + first * stride, count, cols, stride};
  }
};

// The Householder reflectors H_t = I - beta_t v_t v_tᵀ of a nested QR, v_t held in
// V(t, pos_t:) (its entries before pos_t are zero and never read); Q = H_0 H_1 … H_{count-1}.
// end (optional, count entries): v_t's entries from end_t on are zero (stored as zeros),
// so that applying H_t reads and writes entries pos_t:end_t only (a reflector of a row
// that touches few columns, e.g. a foot's Jacobian, stays short); null: end_t = n.
struct Reflectors {
  MatrixRef V;          // n × n
  double* beta = nullptr;
  Index* pos = nullptr;
  Index count = 0;
  const Index* end = nullptr;
};

// one past the last entry of reflector t that may be non-zero (Reflectors::end), of n
inline Index reflector_end(const Reflectors& H, Index t, Index n) {
  return H.end != nullptr ? H.end[t] : n;
}

// --------------------------------------------------------------------------- vectors

// a · b over n entries, summed in eight interleaved partial sums (s_r: the entries
// j ≡ r mod 8 of the whole blocks of eight; then, when four or more entries are left, the
// next four into s_0 … s_3) added pairwise, ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 +
// s7)), then the last (at most three) in order: an order written out, so that the
// compiler may vectorise it without reassociating (the rounding rule), eight chains of
// dependent additions hide each other's latency, and a row of ~30 entries leaves no long
// scalar tail.
inline double dot(const double* a, const double* b, Index n) {
  double s[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  Index j = 0;
  for (; j + 8 <= n; j += 8) {
    for (int r = 0; r < 8; ++r) s[r] += a[j + r] * b[j + r];
  }
  if (j + 4 <= n) {
    for (int r = 0; r < 4; ++r) s[r] += a[j + r] * b[j + r];
    j += 4;
  }
  double acc = ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
  for (; j < n; ++j) acc += a[j] * b[j];
  return acc;
}

template <class T>
inline void swap_entries(T* a, Index i, Index j) {
  T tmp = a[i];
  a[i] = a[j];
  a[j] = tmp;
}

inline void swap_rows(MatrixRef M, Index i, Index j) {
  double* ri = M.row(i);
  double* rj = M.row(j);
  for (Index k = 0; k < M.cols; ++k) {
    const double tmp = ri[k];
    ri[k] = rj[k];
    rj[k] = tmp;
  }
}

// (x, y) ← (c x − s y, s x + c y) entry by entry over n entries: a plane rotation of two
// rows (the one-sided Jacobi SVDs' step)
inline void rotate_rows(double* x, double* y, Index n, double c, double s) {
  for (Index e = 0; e < n; ++e) {
    const double a = x[e], b = y[e];
    x[e] = c * a - s * b;
    y[e] = s * a + c * b;
  }
}

// The Householder reflector H = I − β v vᵀ mapping row[q:n] (of squared norm `exact`)
// onto α e_q, α = −sign(row[q]) √exact: writes v[q:n], sets row[q:n] = (α, 0, …, 0),
// stores in *last one past v's last non-zero entry (a row on few columns keeps its
// trailing zeros, which a reflector need not be applied over) and returns β, with
// vᵀv = 2 (exact − α row[q]) (reflect_column's formula)
inline double make_row_reflector(double* row, Index q, Index n, double exact, double* v,
                                 Index* last) {
  const double alpha = row[q] >= 0.0 ? -std::sqrt(exact) : std::sqrt(exact);
  v[q] = row[q] - alpha;
  const double vtv = 2.0 * (exact - alpha * row[q]);
  Index end = q + 1;
  for (Index j = q + 1; j < n; ++j) {
    v[j] = row[j];
    end = row[j] != 0.0 ? j + 1 : end;
  }
  *last = end;
  row[q] = alpha;
  for (Index j = q + 1; j < n; ++j) row[j] = 0.0;
  return vtv > 0.0 ? 2.0 / vtv : 0.0;
}

// row ← row − β (row · v) v over w entries, skipped when row · v = 0; whether applied
inline bool apply_row_reflector(double* row, const double* v, Index w, double beta) {
  const double dt = dot(row, v, w);
  if (dt == 0.0) return false;
  const double f = beta * dt;
  for (Index j = 0; j < w; ++j) row[j] -= f * v[j];
  return true;
}

// index of the largest of values[start:stop] (the first on ties)
inline Index argmax_from(const double* values, Index start, Index stop) {
  Index p = start;
  double best = values[start];
  for (Index i = start + 1; i < stop; ++i) {
    if (values[i] > best) {
      best = values[i];
      p = i;
    }
  }
  return p;
}

// --------------------------------------------------------------------- reflectors

// One Householder step of a QR held transposed (Tt row k is column k, Tt.cols entries):
// reflects column j's tail Tt(j, j:) (squared norm exact > 0) onto alpha e_1 and applies
// the reflector to the later columns and to t (Tt.cols entries).
inline void reflect_column(MatrixRef Tt, Index j, double* t, double exact) {
  double* cj = Tt.row(j) + j;
  const Index w = Tt.cols - j;
  const double norm = std::sqrt(exact);
  const double c0 = cj[0];
  const double alpha = c0 >= 0.0 ? -norm : norm;
  cj[0] = c0 - alpha;                       // cj is now v; H = I - 2 v vᵀ / vᵀv
  const double vtv = 2.0 * (exact - alpha * c0);
  for (Index k = j + 1; k < Tt.rows; ++k) {
    double* ck = Tt.row(k) + j;
    const double f = 2.0 * dot(ck, cj, w) / vtv;
    for (Index i = 0; i < w; ++i) ck[i] -= f * cj[i];
  }
  double* tj = t + j;
  const double f = 2.0 * dot(tj, cj, w) / vtv;
  for (Index i = 0; i < w; ++i) tj[i] -= f * cj[i];
  cj[0] = alpha;
}

// R z = t[:r] for the upper-triangular R held transposed (R(j, k) = Tt(k, j)), into z[:r]
inline void back_substitute(MatrixRef Tt, const double* t, Index r, double* z) {
  for (Index j = r - 1; j >= 0; --j) {
    double acc = t[j];
    for (Index k = j + 1; k < r; ++k) acc -= Tt(k, j) * z[k];
    z[j] = acc / Tt(j, j);
  }
}

// g ← R⁻¹ R⁻ᵀ g in place for the upper-triangular R held transposed (R(j, k) = Tt(k, j)):
// with g = Kᵀ (p − K z) the correction of the corrected semi-normal equations that
// refines a least-squares solution z of K = Q R. Householder QR is backward stable in
// norm only: rows of K far smaller than its norm (zero rows with targets, tasks decades
// apart in one level) are read with errors of ε ‖K‖ and their large targets leak into
// Qᵀ p; Kᵀ (p − K z), formed row by row, has no such term.
inline void csne_correction(MatrixRef Tt, double* g, Index r) {
  for (Index j = 0; j < r; ++j) {           // Rᵀ w = g (forward)
    double acc = g[j];
    for (Index k = 0; k < j; ++k) acc -= Tt(j, k) * g[k];
    g[j] = acc / Tt(j, j);
  }
  for (Index j = r - 1; j >= 0; --j) {      // R δ = w (backward)
    double acc = g[j];
    for (Index k = j + 1; k < r; ++k) acc -= Tt(k, j) * g[k];
    g[j] = acc / Tt(j, j);
  }
}

// z[:r] += R⁻¹ R⁻ᵀ g (csne_correction), g overwritten
inline void refine_step(MatrixRef Tt, double* g, Index r, double* z) {
  csne_correction(Tt, g, r);
  for (Index j = 0; j < r; ++j) z[j] += g[j];
}

// v = Qᵀ v (transposed: H_0 first) or v = Q v (H_{count-1} first) in place, v of n entries
inline void apply_reflectors(double* v, Index n, const Reflectors& H, bool transposed) {
  for (Index i = 0; i < H.count; ++i) {
    const Index t = transposed ? i : H.count - 1 - i;
    const Index q = H.pos[t];
    const double* vt = H.V.row(t) + q;
    double* vq = v + q;
    const Index w = reflector_end(H, t, n) - q;
    const double f = H.beta[t] * dot(vt, vq, w);
    if (f != 0.0) {
      for (Index c = 0; c < w; ++c) vq[c] -= f * vt[c];
    }
  }
}

inline void apply_qt(double* v, Index n, const Reflectors& H) { apply_reflectors(v, n, H, true); }
inline void apply_q(double* v, Index n, const Reflectors& H) { apply_reflectors(v, n, H, false); }

// ------------------------------------------------------------------ least squares

// Floats of small_least_squares' scratch for m rows and r unknowns: the matrix held
// transposed, r (m + r), and its right-hand side, m + r.
inline Index small_least_squares_scratch(Index m, Index r) { return r * (m + r) + m + r; }

// min ‖L[:m, :r] z - rhs‖² + mu2 ‖z‖², by Householder QR of [L; √mu2 I] held transposed,
// into z[:r]; undamped (mu2 = 0), one step of refinement by the corrected semi-normal
// equations (refine_step). L: lower trapezoidal or any m × r; scratch of
// small_least_squares_scratch.
inline void small_least_squares(MatrixRef L, const double* rhs, Index m, Index r, double mu2,
                                double* z, double* scratch) {
  const Index rows = mu2 > 0.0 ? m + r : m;
  MatrixRef Tt{scratch, r, rows, rows};
  double* t = scratch + r * rows;           // the reflectors' length
  for (Index j = 0; j < r; ++j)
    for (Index i = 0; i < rows; ++i) Tt(j, i) = 0.0;
  for (Index i = 0; i < rows; ++i) t[i] = 0.0;
  for (Index i = 0; i < m; ++i) {
    for (Index j = 0; j < r; ++j) Tt(j, i) = L(i, j);
    t[i] = rhs[i];
  }
  if (mu2 > 0.0) {
    const double s = std::sqrt(mu2);
    for (Index j = 0; j < r; ++j) Tt(j, m + j) = s;
  }
  for (Index j = 0; j < r; ++j) {
    const double* tail = Tt.row(j) + j;
    const double exact = dot(tail, tail, rows - j);
    if (exact > 0.0) reflect_column(Tt, j, t, exact);
  }
  back_substitute(Tt, t, r, z);
  if (mu2 == 0.0) {
    // the residual row by row (in t's m entries), the correction in the r after them
    double* res = t;
    double* g = t + m;
    for (Index i = 0; i < m; ++i) {
      double acc = rhs[i];
      for (Index j = 0; j < r; ++j) acc -= L(i, j) * z[j];
      res[i] = acc;
    }
    for (Index j = 0; j < r; ++j) {
      double acc = 0.0;
      for (Index i = 0; i < m; ++i) acc += L(i, j) * res[i];
      g[j] = acc;
    }
    refine_step(Tt, g, r, z);
  }
}

// Floats of full_rank_least_squares' scratch for m rows on d free columns.
inline Index full_rank_scratch(Index m, Index d) { return d * m + m + 2 * d; }

// One level with m ≥ d rows B[s0:s0+m, col:] on its d = n - col free coordinates:
// Householder QR with column pivoting (held transposed), with the rank test of the
// row-pivoted path (pivot norm > tol). When all d pivots pass, the level has full
// column rank: its least-squares solution R⁻¹ Qᵀ rhs, refined by one step of the
// corrected semi-normal equations (refine_step), is written into y[col:] and true
// returned. Otherwise nothing is written and false returned (B is never modified).
// *margin receives the smallest pivot norm. Scratch: full_rank_scratch(m, d) floats,
// d Index.
inline bool full_rank_least_squares(MatrixRef B, Index s0, Index m, Index col, const double* rhs,
                                    double tol, double* y, double* margin, double* scratch,
                                    Index* iscratch) {
  const Index n = B.cols;
  const Index d = n - col;
  *margin = kInf;
  MatrixRef Tt{scratch, d, m, m};
  double* t = scratch + d * m;
  double* norms = t + m;
  double* z = norms + d;
  Index* perm = iscratch;
  for (Index i = 0; i < m; ++i) {
    const double* row = B.row(s0 + i);
    for (Index j = 0; j < d; ++j) Tt(j, i) = row[col + j];
    t[i] = rhs[i];
  }
  for (Index j = 0; j < d; ++j) {
    norms[j] = dot(Tt.row(j), Tt.row(j), m);
    perm[j] = j;
  }
  for (Index j = 0; j < d; ++j) {
    const Index p = argmax_from(norms, j, d);
    if (p != j) {
      swap_rows(Tt, j, p);
      swap_entries(norms, j, p);
      swap_entries(perm, j, p);
    }
    double* cj = Tt.row(j) + j;
    const Index w = m - j;
    const double exact = dot(cj, cj, w);     // exactly (downdated norms lose accuracy)
    if (!(std::sqrt(exact) > tol) || tol <= 0.0) return false;
    *margin = std::fmin(*margin, std::sqrt(exact));
    // reflect_column's step with the pivot norms downdated in the same pass
    const double norm = std::sqrt(exact);
    const double c0 = cj[0];
    const double alpha = c0 >= 0.0 ? -norm : norm;
    cj[0] = c0 - alpha;
    const double vtv = 2.0 * (exact - alpha * c0);
    for (Index k = j + 1; k < d; ++k) {
      double* ck = Tt.row(k) + j;
      const double f = 2.0 * dot(ck, cj, w) / vtv;
      for (Index i = 0; i < w; ++i) ck[i] -= f * cj[i];
      norms[k] -= ck[0] * ck[0];
    }
    double* tj = t + j;
    const double f = 2.0 * dot(tj, cj, w) / vtv;
    for (Index i = 0; i < w; ++i) tj[i] -= f * cj[i];
    cj[0] = alpha;
  }
  back_substitute(Tt, t, d, z);
  // one step of refinement: the residual row by row (in t), the correction in norms
  for (Index i = 0; i < m; ++i) {
    const double* row = B.row(s0 + i);
    double acc = rhs[i];
    for (Index j = 0; j < d; ++j) acc -= row[col + perm[j]] * z[j];
    t[i] = acc;
  }
  for (Index j = 0; j < d; ++j) {
    double acc = 0.0;
    for (Index i = 0; i < m; ++i) acc += B(s0 + i, col + perm[j]) * t[i];
    norms[j] = acc;
  }
  refine_step(Tt, norms, d, z);
  for (Index j = 0; j < d; ++j) y[col + perm[j]] = z[j];
  return true;
}

// ------------------------------------------------------------------------ Cholesky

// G[:m, :m] = L Lᵀ in place (the lower triangle read and overwritten by L); false at a
// pivot that is not positive (G not positive definite).
inline bool cholesky_lower(MatrixRef G, Index m) {
  for (Index a = 0; a < m; ++a) {
    for (Index b = 0; b <= a; ++b) {
      double acc = G(a, b);
      for (Index c = 0; c < b; ++c) acc -= G(a, c) * G(b, c);
      if (a == b) {
        if (!(acc > 0.0)) return false;
        G(a, a) = std::sqrt(acc);
      } else {
        G(a, b) = acc / G(b, b);
      }
    }
  }
  return true;
}

// t = (L Lᵀ)⁻¹ t in place, L in the lower triangle of L[:m, :m]
inline void cholesky_solve(MatrixRef L, double* t, Index m) {
  for (Index a = 0; a < m; ++a) {
    double acc = t[a];
    for (Index c = 0; c < a; ++c) acc -= L(a, c) * t[c];
    t[a] = acc / L(a, a);
  }
  for (Index a = m - 1; a >= 0; --a) {
    double acc = t[a];
    for (Index c = a + 1; c < m; ++c) acc -= L(c, a) * t[c];
    t[a] = acc / L(a, a);
  }
}

// ---------------------------------------------------------------- free directions

// Z row i = Qᵀ e_{cols[i]} for i < m (Z's rows hold n = H.V.cols entries), whose entries
// from col on are the rows cols of the free directions Q[:, col:] (drop_fixed moves them
// to the front); and g = Qᵀ g in place when g is given (n entries). The loop runs over the
// reflectors outside and the vectors inside: several interleaved sweeps hide the latency
// of one sweep's chain of dependent dot products.
inline void free_directions(const Index* cols, Index m, MatrixRef Z, const Reflectors& H,
                            double* g) {
  const Index n = H.V.cols;
  for (Index i = 0; i < m; ++i) {
    double* Zi = Z.row(i);
    for (Index k = 0; k < n; ++k) Zi[k] = 0.0;
    Zi[cols[i]] = 1.0;
  }
  for (Index t = 0; t < H.count; ++t) {
    const Index q = H.pos[t];
    const double* vt = H.V.row(t) + q;
    const double bt = H.beta[t];
    const Index w = reflector_end(H, t, n) - q;
    for (Index i = 0; i < m; ++i) {
      double* zq = Z.row(i) + q;
      const double f = bt * dot(vt, zq, w);
      if (f != 0.0) {
        for (Index c = 0; c < w; ++c) zq[c] -= f * vt[c];
      }
    }
    if (g != nullptr) {
      double* gq = g + q;
      const double f = bt * dot(vt, gq, w);
      if (f != 0.0) {
        for (Index c = 0; c < w; ++c) gq[c] -= f * vt[c];
      }
    }
  }
}

// Z(i, :n - col) = Z(i, col:) for i < m: the free part of each rotated vector to the front
inline void drop_fixed(MatrixRef Z, Index m, Index col) {
  if (col <= 0) return;
  for (Index i = 0; i < m; ++i) {
    double* Zi = Z.row(i);
    for (Index k = 0; k < Z.cols - col; ++k) Zi[k] = Zi[col + k];
  }
}

// v = (I - Z_Uᵀ Z_U)⁻¹ v in place: v + Z_Uᵀ (L Lᵀ)⁻¹ Z_U v, Z_U in Zu[:nu, :d], L (the
// Cholesky factor of I - Z_U Z_Uᵀ) in G[:nu, :nu]; scratch t (nu entries)
inline void woodbury_apply(double* v, MatrixRef Zu, MatrixRef G, Index nu, Index d, double* t) {
  for (Index a = 0; a < nu; ++a) t[a] = dot(Zu.row(a), v, d);
  cholesky_solve(G, t, nu);
  for (Index a = 0; a < nu; ++a) {
    const double ta = t[a];
    const double* Za = Zu.row(a);
    for (Index c = 0; c < d; ++c) v[c] += ta * Za[c];
  }
}

// ---------------------------------------------------------------------- unit rows

// The unit-rows step is taken only when the smallest eigenvalue of I - Z_U Z_Uᵀ exceeds
// this: the normal equations' κ² is then below 1 / this (their rounding ~eps κ² relative).
constexpr double kUnitRowsGap = 1e-3;

// Whether the rows B[s0:s1] are unit rows (one non-zero each, of one magnitude, on
// distinct columns): their magnitude s, else -1. cover[c] is then the row (offset from
// s0) on column c, -1 where none is (cover: B.cols entries, written). columns (optional,
// indexed by B's rows): a row's entry c ≥ 0 says the caller knows every entry of that
// row but column c to be zero (its row is then not scanned); -1: scan it.
inline double unit_rows_of(MatrixRef B, Index s0, Index s1, Index* cover,
                           const Index* columns = nullptr) {
  const Index n = B.cols;
  for (Index c = 0; c < n; ++c) cover[c] = -1;
  double s = -1.0;
  for (Index i = 0; i < s1 - s0; ++i) {
    const double* row = B.row(s0 + i);
    Index nz = 0;
    Index at = 0;
    if (columns != nullptr && columns[s0 + i] >= 0) {
      at = columns[s0 + i];
      nz = row[at] != 0.0 ? 1 : 0;
    } else {
      for (Index c = 0; c < n; ++c) {
        const bool nonzero = row[c] != 0.0;
        nz += nonzero ? 1 : 0;
        at += nonzero ? c : 0;
      }
    }
    if (nz != 1 || cover[at] >= 0) return -1.0;
    const double a = std::fabs(row[at]);
    if (s < 0.0) {
      s = a;
    } else if (a != s) {
      return -1.0;
    }
    cover[at] = i;
  }
  return s;
}

// The least-squares step of a level of unit rows S (±s e_cᵀ, distinct columns) on the
// free coordinates Z = Q[:, col:] (Q = H_0 … H_{count-1}, orthonormal). cover[c] < 0 marks
// the columns U no row covers. SᵀS = s² (I - P_U), so min ‖S Z p - t‖ solves
// (I - Z_Uᵀ Z_U) p = h, h = Zᵀ g, g = Sᵀ c / s² (given, n entries, overwritten), by
// Woodbury: p = h + Z_Uᵀ (I - Z_U Z_Uᵀ)⁻¹ Z_U h. With the fixed coordinates yfix = y[:col]
// of the levels above (x_p = Q [yfix; 0]), h = (Qᵀ g)[col:] + Σ_u (x_p)_u (Qᵀ e_u)[col:],
// (x_p)_u = (Qᵀ e_u)[:col] · yfix, which is Zᵀ Sᵀ (c - S x_p) / s².
// Taken only when I - Z_U Z_Uᵀ - kUnitRowsGap I is positive definite (then
// σ_min(S Z) ≥ s √gap). Writes p[:n - col]; returns |U|, or -1 when the test fails (p may
// be written). yfix null: the targets are taken as given (no fixed part). Scratch: Zu
// (≥ |U| × n), G (≥ max(1, 2|U|) × n), ucols (n Index).
inline Index unit_rows_solve(const Index* cover, double* g, Index col, double* p,
                             const Reflectors& H, MatrixRef Zu, MatrixRef G,
                             const double* yfix, Index* ucols) {
  const Index n = H.V.cols;
  const Index d = n - col;
  Index nu = 0;
  for (Index u = 0; u < n; ++u) {
    if (cover[u] < 0) ucols[nu++] = u;
  }
  free_directions(ucols, nu, Zu, H, g);
  for (Index c = 0; c < d; ++c) p[c] = g[col + c];
  if (col > 0 && yfix != nullptr) {
    for (Index i = 0; i < nu; ++i) {
      const double xu = dot(Zu.row(i), yfix, col);
      const double* Zi = Zu.row(i) + col;
      for (Index c = 0; c < d; ++c) p[c] += xu * Zi[c];
    }
  }
  drop_fixed(Zu, nu, col);
  if (nu == 0) return 0;
  // G = I - Z_U Z_Uᵀ (lower triangle), and below it G - gap I
  for (Index a = 0; a < nu; ++a) {
    for (Index b = 0; b <= a; ++b) {
      const double v = (a == b ? 1.0 : 0.0) - dot(Zu.row(a), Zu.row(b), d);
      G(a, b) = v;
      G(nu + a, b) = a == b ? v - kUnitRowsGap : v;
    }
  }
  if (!cholesky_lower(G.middle_rows(nu, nu), nu)) return -1;
  cholesky_lower(G, nu);
  woodbury_apply(p, Zu, G, nu, d, g);       // scratch g[:nu]
  return nu;
}

}  // namespace prioik
