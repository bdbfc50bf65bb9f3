// The robot row writers (rows.hpp): each operation in the order of
// robots/_rows_kernel.py, so that the roundings are the same.
#include "prioik/rows.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace prioik::rows {

namespace {

constexpr double kPi = 3.141592653589793;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Python's min and max on two floats (the first argument on a tie)
inline double min2(double a, double b) { return b < a ? b : a; }
inline double max2(double a, double b) { return b > a ? b : a; }

// out[o:o+3] = log(R) from its nine entries: theta = atan2(|w|/2, (tr R - 1)/2) with
// w = vee(R - R^T) = 2 sin(theta) u; theta u = theta / (2 sin theta) w (a Taylor series
// below theta = 1e-4); near pi, where sin(theta) vanishes, u from the symmetric part
// R + R^T = 2 cos(theta) I + 2 (1 - cos theta) u u^T, its sign from w.
void log3_entries(double r00, double r01, double r02, double r10, double r11, double r12,
                  double r20, double r21, double r22, const Vector& out, Index o) {
  const double wx = r21 - r12;
  const double wy = r02 - r20;
  const double wz = r10 - r01;
  const double s = 0.5 * std::sqrt(wx * wx + wy * wy + wz * wz);
  const double c = 0.5 * (r00 + r11 + r22 - 1.0);
  const double theta = std::atan2(s, c);
  if (theta < 1e-4) {
    const double f = 0.5 + theta * theta / 12.0;
    out[o] = f * wx;
    out[o + 1] = f * wy;
    out[o + 2] = f * wz;
    return;
  }
  if (theta < kPi - 1e-3) {
    const double f = 0.5 * theta / s;
    out[o] = f * wx;
    out[o + 1] = f * wy;
    out[o + 2] = f * wz;
    return;
  }
  // u u^T = (R + R^T - 2c I) / (2 (1 - c)); the column of the largest diagonal
  const double one_c = 2.0 * (1.0 - c);
  double u0, u1, u2;
  if (r00 >= r11 && r00 >= r22) {
    u0 = 2.0 * r00 - 2.0 * c; u1 = r10 + r01; u2 = r20 + r02;
  } else if (r11 >= r22) {
    u0 = r01 + r10; u1 = 2.0 * r11 - 2.0 * c; u2 = r21 + r12;
  } else {
    u0 = r02 + r20; u1 = r12 + r21; u2 = 2.0 * r22 - 2.0 * c;
  }
  u0 /= one_c;
  u1 /= one_c;
  u2 /= one_c;
  const double norm = std::sqrt(u0 * u0 + u1 * u1 + u2 * u2);
  const double sign = u0 * wx + u1 * wy + u2 * wz >= 0.0 ? 1.0 : -1.0;
  out[o] = sign * theta * u0 / norm;
  out[o + 1] = sign * theta * u1 / norm;
  out[o + 2] = sign * theta * u2 / norm;
}

// (A B^T)(i, j) of two 3 x 3 matrices
inline double rrt(const ConstMatrix& A, const ConstMatrix& B, Index i, Index j) {
  return A(i, 0) * B(j, 0) + A(i, 1) * B(j, 1) + A(i, 2) * B(j, 2);
}

// Q's row r as a vector
inline Vector q_row(const Matrix& Q, Index r) { return Vector{&Q(r, 0), Q.cols, Q.cs}; }

// world axes of a joint-frame vector y: R (R_jf^T y), R_jf^T in geo's rotation rows
void drift_to_world(const Matrix& Q, Index o, const ConstMatrix& R, const ConstMatrix& geo,
                    double y0, double y1, double y2) {
  const Index g = GEO_ROTATION;
  const double f0 = geo(g, 0) * y0 + geo(g + 1, 0) * y1 + geo(g + 2, 0) * y2;
  const double f1 = geo(g, 1) * y0 + geo(g + 1, 1) * y1 + geo(g + 2, 1) * y2;
  const double f2 = geo(g, 2) * y0 + geo(g + 1, 2) * y1 + geo(g + 2, 2) * y2;
  for (Index i = 0; i < 3; ++i) Q(DRIFT, o + i) = R(i, 0) * f0 + R(i, 1) * f1 + R(i, 2) * f2;
}

// The drift J' q' of a frame task's rows at s (LOCAL_WORLD_ALIGNED, as pinocchio's
// getFrameClassicalAcceleration): in the joint frame the point r moves at v + w x r and
// its classical acceleration is a + alpha x r + w x v_r; the angular rows take alpha.
void frame_drift(const FrameArgs& f, Index s, Index mode) {
  const ConstMatrix& geo = f.geo;
  const double r0 = geo(GEO_POINT, 0), r1 = geo(GEO_POINT, 1), r2 = geo(GEO_POINT, 2);
  const ConstVector& vj = f.vj;
  const ConstVector& aj = f.aj;
  const double w0 = vj[3], w1 = vj[4], w2 = vj[5];
  const double al0 = aj[3], al1 = aj[4], al2 = aj[5];
  const double v0 = vj[0] + w1 * r2 - w2 * r1;
  const double v1 = vj[1] + w2 * r0 - w0 * r2;
  const double v2 = vj[2] + w0 * r1 - w1 * r0;
  const double a0 = aj[0] + al1 * r2 - al2 * r1 + w1 * v2 - w2 * v1;
  const double a1 = aj[1] + al2 * r0 - al0 * r2 + w2 * v0 - w0 * v2;
  const double a2 = aj[2] + al0 * r1 - al1 * r0 + w0 * v1 - w1 * v0;
  if (mode != ORIENTATION) drift_to_world(f.Q, s, f.R, geo, a0, a1, a2);
  if (mode != POSITION) drift_to_world(f.Q, mode == POSE ? s + 3 : s, f.R, geo, al0, al1, al2);
}

// A frame task's rows s .. s + nrows zeroed in A (and their drift, if zero_drift)
void zero_rows(const Matrix& A, const Matrix& Q, Index s, Index nrows, bool zero_drift) {
  for (Index i = 0; i < nrows; ++i) {
    for (Index j = 0; j < A.cols; ++j) A(s + i, j) = 0.0;
    if (zero_drift) Q(DRIFT, s + i) = 0.0;
  }
}

// The position rows of a frame task (the columns spec[SPEC_COLS:]; the others are the
// caller's to zero)
void position_rows(const FrameArgs& f, const ConstVector& x, const ConstVector& xd,
                   const ConstVector& xdd, bool rates) {
  const Index s = f.spec[SPEC_START];
  const ConstMatrix& R = f.R;
  const double off0 = f.geo(GEO_OFFSET, 0), off1 = f.geo(GEO_OFFSET, 1),
               off2 = f.geo(GEO_OFFSET, 2);
  const double p0 = f.t[0] + R(0, 0) * off0 + R(0, 1) * off1 + R(0, 2) * off2;
  const double p1 = f.t[1] + R(1, 0) * off0 + R(1, 1) * off1 + R(1, 2) * off2;
  const double p2 = f.t[2] + R(2, 0) * off0 + R(2, 1) * off1 + R(2, 2) * off2;
  const ConstMatrix& J = f.J;
  for (Index k = SPEC_COLS; k < f.spec.size; ++k) {
    const Index c = f.spec[k];
    const double wx = J(3, c), wy = J(4, c), wz = J(5, c);
    f.A(s, c) = J(0, c) + wy * p2 - wz * p1;
    f.A(s + 1, c) = J(1, c) + wz * p0 - wx * p2;
    f.A(s + 2, c) = J(2, c) + wx * p1 - wy * p0;
  }
  f.Q(ERROR, s) = x[0] - p0;
  f.Q(ERROR, s + 1) = x[1] - p1;
  f.Q(ERROR, s + 2) = x[2] - p2;
  for (Index i = 0; i < 3; ++i) {
    f.Q(VELOCITY_REF, s + i) = rates ? xd[i] : 0.0;
    f.Q(FEEDFORWARD, s + i) = rates ? xdd[i] : 0.0;
  }
}

// The orientation rows at o: J_ang on the columns spec[SPEC_COLS:], error log(R* R^T),
// w, wd
void orientation_rows(const FrameArgs& f, Index o, const ConstMatrix& Rstar,
                      const ConstVector& w, const ConstVector& wd) {
  for (Index k = SPEC_COLS; k < f.spec.size; ++k) {
    const Index c = f.spec[k];
    f.A(o, c) = f.J(3, c);
    f.A(o + 1, c) = f.J(4, c);
    f.A(o + 2, c) = f.J(5, c);
  }
  const ConstMatrix& R = f.R;
  log3_entries(rrt(Rstar, R, 0, 0), rrt(Rstar, R, 0, 1), rrt(Rstar, R, 0, 2),
               rrt(Rstar, R, 1, 0), rrt(Rstar, R, 1, 1), rrt(Rstar, R, 1, 2),
               rrt(Rstar, R, 2, 0), rrt(Rstar, R, 2, 1), rrt(Rstar, R, 2, 2),
               q_row(f.Q, ERROR), o);
  for (Index i = 0; i < 3; ++i) {
    f.Q(VELOCITY_REF, o + i) = w[i];
    f.Q(FEEDFORWARD, o + i) = wd[i];
  }
}

}  // namespace

void log3(const ConstMatrix& R, const Vector& out, Index o) {
  log3_entries(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1),
               R(2, 2), out, o);
}

void point_rows(const FrameArgs& f, const ConstVector& x, const ConstVector& xd,
                const ConstVector& xdd, bool rates) {
  const Index s = f.spec[SPEC_START];
  const bool zero_drift = f.spec[SPEC_ZERO_DRIFT] != 0;
  zero_rows(f.A, f.Q, s, 3, zero_drift);
  position_rows(f, x, xd, xdd, rates);
  if (!zero_drift) frame_drift(f, s, POSITION);
}

void frame_rows(const FrameArgs& f, const ConstVector& x, const ConstVector& xd,
                const ConstVector& xdd, const ConstMatrix& Rstar, const ConstVector& w,
                const ConstVector& wd) {
  const Index s = f.spec[SPEC_START];
  const Index mode = f.spec[SPEC_MODE];
  const bool zero_drift = f.spec[SPEC_ZERO_DRIFT] != 0;
  zero_rows(f.A, f.Q, s, mode == POSE ? 6 : 3, zero_drift);
  if (!zero_drift) frame_drift(f, s, mode);
  if (mode != ORIENTATION) position_rows(f, x, xd, xdd, true);
  if (mode != POSITION) orientation_rows(f, mode == POSE ? s + 3 : s, Rstar, w, wd);
}

void com_rows(const Matrix& A, const Matrix& Q, Index s, const ConstMatrix& Jcom,
              const ConstVector& com, const ConstVector& acom, const ConstIndices& axes,
              const ConstVector& x, const ConstVector& xd, const ConstVector& xdd,
              bool zero_drift) {
  for (Index i = 0; i < axes.size; ++i) {
    const Index a = axes[i];
    for (Index j = 0; j < A.cols; ++j) A(s + i, j) = Jcom(a, j);
    Q(ERROR, s + i) = x[i] - com[a];
    Q(VELOCITY_REF, s + i) = xd[i];
    Q(FEEDFORWARD, s + i) = xdd[i];
    Q(DRIFT, s + i) = zero_drift ? 0.0 : acom[a];
  }
}

void posture_error(const Matrix& Q, Index s, const ConstVector& q, const ConstVector& q_ref,
                   const ConstIndices& iq) {
  for (Index i = 0; i < iq.size; ++i) {
    Q(ERROR, s + i) = q_ref[iq[i]] - q[iq[i]];
    Q(VELOCITY_REF, s + i) = 0.0;
    Q(FEEDFORWARD, s + i) = 0.0;
    Q(DRIFT, s + i) = 0.0;
  }
}

void actuated_positions(const ConstVector& q, const ConstIndices& iq, const Vector& out) {
  for (Index k = 0; k < iq.size; ++k) out[k] = iq[k] >= 0 ? q[iq[k]] : 0.0;
}

Index limit_activation_rows(const Matrix& A, const Matrix& Q, Index s, Index nb,
                            const ConstVector& qa, const ConstVector& lo,
                            const ConstVector& hi, const ConstVector& width, double kp,
                            double kd) {
  Index active = 0;
  for (Index k = 0; k < qa.size; ++k) {
    const Index r = s + k;
    double e = 0.0, g = 0.0;
    bool on = false;
    if (std::isfinite(lo[k]) && std::isfinite(hi[k])) {
      const double y_lo = lo[k] + width[k] - qa[k];
      const double y_hi = qa[k] - (hi[k] - width[k]);
      if (y_lo > 0.0) {
        const double sig = min2(y_lo / width[k], 1.0);
        e = sig * y_lo;
        g = sig;
        on = true;
      } else if (y_hi > 0.0) {
        const double sig = min2(y_hi / width[k], 1.0);
        e = -sig * y_hi;
        g = sig;
        on = true;
      }
    }
    A(r, nb + k) = on ? 1.0 : 0.0;
    Q(ERROR, r) = e;
    Q(KP, r) = on ? kp : 0.0;
    Q(KD, r) = g * kd;
    Q(VELOCITY_REF, r) = 0.0;
    Q(FEEDFORWARD, r) = 0.0;
    Q(DRIFT, r) = 0.0;
    if (on) ++active;
  }
  return active;
}

void acceleration_bounds(const Vector& lower, const Vector& upper, Index s,
                         const ConstVector& qa, const ConstVector& va, const ConstVector& lo,
                         const ConstVector& hi, const ConstVector& vmax, double T, double dt,
                         bool position, bool velocity) {
  for (Index k = 0; k < qa.size; ++k) {
    const double q = qa[k];
    const double v = va[k];
    double p_lo = -kInf, p_hi = kInf;
    if (position) {
      const double h_lo = 2.0 * (lo[k] - q - v * T) / (T * T);
      const double h_hi = 2.0 * (hi[k] - q - v * T) / (T * T);
      const double d_hi = max2(hi[k] - q, 1e-9);
      const double d_lo = max2(q - lo[k], 1e-9);
      p_hi = min2(h_hi, (hi[k] - q - v * dt) / (dt * dt));
      p_lo = max2(h_lo, (lo[k] - q - v * dt) / (dt * dt));
      if (v > 0.0 && h_hi < -v / T) p_hi = min2(p_hi, -v * v / (2.0 * d_hi));
      if (v < 0.0 && h_lo > -v / T) p_lo = max2(p_lo, v * v / (2.0 * d_lo));
    }
    double v_lo = -kInf, v_hi = kInf;
    if (velocity && std::isfinite(vmax[k])) {
      v_lo = (-vmax[k] - v) / dt;
      v_hi = (vmax[k] - v) / dt;
    }
    double a = max2(p_lo, v_lo);
    double b = min2(p_hi, v_hi);
    if (a > b) {
      double mid = min2(max2(v > 0.0 ? p_hi : p_lo, v_lo), v_hi);
      if (!std::isfinite(mid)) mid = 0.0;
      a = mid;
      b = mid;
    }
    lower[s + k] = a;
    upper[s + k] = b;
  }
}

void velocity_bounds(const Vector& lower, const Vector& upper, Index s, const ConstVector& qa,
                     const ConstVector& lo, const ConstVector& hi, const ConstVector& vmax,
                     double T, bool position, bool velocity) {
  for (Index k = 0; k < qa.size; ++k) {
    double a = -kInf, b = kInf;
    if (position) {
      a = (lo[k] - qa[k]) / T;
      b = (hi[k] - qa[k]) / T;
    }
    if (velocity) {
      a = max2(a, -vmax[k]);
      b = min2(b, vmax[k]);
    }
    lower[s + k] = min2(a, b);
    upper[s + k] = b;
  }
}

void region_rows(const Matrix& A, const Vector& lower, const Vector& upper, Index s,
                 const ConstMatrix& C, const ConstMatrix& Jp, const ConstVector& p,
                 double psign, const ConstVector& v, const ConstVector& drift,
                 const ConstVector& lo, const ConstVector& hi, const Vector& y,
                 const Vector& yd, const ConstVector& vmax, double T, double dt, bool accel) {
  const Index n = Jp.cols;
  for (Index i = 0; i < C.rows; ++i) {
    const double c0 = C(i, 0), c1 = C(i, 1), c2 = C(i, 2);
    for (Index c = 0; c < n; ++c) A(s + i, c) = c0 * Jp(0, c) + c1 * Jp(1, c) + c2 * Jp(2, c);
    y[i] = psign * (c0 * p[0] + c1 * p[1] + c2 * p[2]);
  }
  const ConstVector yc{y.data, y.size, y.stride};
  if (!accel) {
    velocity_bounds(lower, upper, s, yc, lo, hi, vmax, T, true, false);
    return;
  }
  for (Index i = 0; i < C.rows; ++i) {
    double acc = 0.0;
    for (Index c = 0; c < n; ++c) acc += A(s + i, c) * v[c];
    yd[i] = acc;
  }
  const ConstVector ydc{yd.data, yd.size, yd.stride};
  acceleration_bounds(lower, upper, s, yc, ydc, lo, hi, vmax, T, dt, true, false);
  for (Index i = 0; i < C.rows; ++i) {
    const double cd = C(i, 0) * drift[0] + C(i, 1) * drift[1] + C(i, 2) * drift[2];
    lower[s + i] -= cd;
    upper[s + i] -= cd;
  }
}

namespace {
inline ConstVector lim_row(const ConstMatrix& lim, Index r) {
  return ConstVector{&lim(r, 0), lim.cols, lim.cs};
}
}  // namespace

void bounds_at(const Vector& lower, const Vector& upper, const ConstVector& q,
               const ConstVector& v, const ConstIndices& iq, const ConstMatrix& lim,
               const ConstVector& params, const Vector& qa) {
  const Index na = iq.size;
  actuated_positions(q, iq, qa);
  const ConstVector qac{qa.data, qa.size, qa.stride};
  const Index s = static_cast<Index>(params[0]);
  if (params[5] != 0.0) {
    const ConstVector va{v.data + (v.size - na) * v.stride, na, v.stride};
    acceleration_bounds(lower, upper, s, qac, va, lim_row(lim, 0), lim_row(lim, 1),
                        lim_row(lim, 2), params[1], params[2], params[3] != 0.0,
                        params[4] != 0.0);
  } else {
    velocity_bounds(lower, upper, s, qac, lim_row(lim, 0), lim_row(lim, 1), lim_row(lim, 2),
                    params[1], params[3] != 0.0, params[4] != 0.0);
  }
}

Index activation_at(const Matrix& A, const Matrix& Q, const ConstVector& q,
                    const ConstIndices& iq, const ConstMatrix& lim, const ConstVector& params,
                    const Vector& qa) {
  actuated_positions(q, iq, qa);
  const ConstVector qac{qa.data, qa.size, qa.stride};
  return limit_activation_rows(A, Q, static_cast<Index>(params[0]),
                               static_cast<Index>(params[1]), qac, lim_row(lim, 0),
                               lim_row(lim, 1), lim_row(lim, 2), params[2], params[3]);
}

void velocity_targets(const Vector& b, const ConstMatrix& Q) {
  for (Index i = 0; i < b.size; ++i) b[i] = Q(VELOCITY_REF, i) + Q(KP, i) * Q(ERROR, i);
}

void acceleration_targets(const ConstMatrix& A, const Vector& b, const ConstMatrix& Q,
                          const ConstVector& v) {
  for (Index i = 0; i < b.size; ++i) {
    double jv = 0.0;
    for (Index j = 0; j < A.cols; ++j) jv += A(i, j) * v[j];
    b[i] = Q(KD, i) * (Q(VELOCITY_REF, i) - jv) + Q(KP, i) * Q(ERROR, i) + Q(FEEDFORWARD, i) -
           Q(DRIFT, i);
  }
}

bool state_is_valid(const ConstVector& q, const ConstVector& v, const ConstIndices& unit,
                    double tol) {
  for (Index i = 0; i < q.size; ++i)
    if (!std::isfinite(q[i])) return false;
  for (Index i = 0; i < v.size; ++i)
    if (!std::isfinite(v[i])) return false;
  for (Index p = 0; p + 1 < unit.size; p += 2) {
    double acc = 0.0;
    for (Index i = unit[p]; i < unit[p] + unit[p + 1]; ++i) acc += q[i] * q[i];
    if (std::abs(std::sqrt(acc) - 1.0) > tol) return false;
  }
  return true;
}

}  // namespace prioik::rows
