// The robot row writers: robot state -> one task's rows of a stack (prioik.robots.rows).
//
// Each function writes one task's rows of a stack's A (m x n_v), lower/upper or b, and
// the per-row quantities Q (6 x m: error, reference velocity, feed-forward, drift, K_p,
// K_d; rows named by QRow) from views of a pinocchio Data: the world-frame joint
// Jacobians J (6 x n_v, linear rows first), a frame placement (t, R), the parent joint's
// spatial velocity and acceleration at zero joint acceleration (linear then angular,
// joint frame), Jcom, com, acom. Views carry their strides (pinocchio's matrices are
// column-major), so no array is copied; nothing is allocated. Every index a writer
// follows (a row start, a column of spec, an entry of iq or unit) is the caller's to
// keep in range: the Python bindings check them before a writer runs.
//
// Arithmetic: the operations of robots/_rows_kernel.py in its order, IEEE double,
// no contraction (core/CMakeLists.txt), so that the answers equal the numba kernels'.
#pragma once

#include <cstdint>

namespace prioik::rows {

using Index = std::int64_t;

// A strided view of a matrix or a vector (element (i, j) at data[i * rs + j * cs]).
template <class T>
struct MatrixView {
  T* data = nullptr;
  Index rows = 0, cols = 0;
  Index rs = 0, cs = 0;
  T& operator()(Index i, Index j) const { return data[i * rs + j * cs]; }
};

template <class T>
struct VectorView {
  T* data = nullptr;
  Index size = 0;
  Index stride = 1;
  T& operator[](Index i) const { return data[i * stride]; }
};

using Matrix = MatrixView<double>;
using ConstMatrix = MatrixView<const double>;
using Vector = VectorView<double>;
using ConstVector = VectorView<const double>;
using ConstIndices = VectorView<const std::int64_t>;

// rows of the per-row array Q (6 x m)
enum QRow : Index { ERROR = 0, VELOCITY_REF = 1, FEEDFORWARD = 2, DRIFT = 3, KP = 4, KD = 5 };

// row sets of frame_rows
enum FrameMode : Index { POSITION = 0, ORIENTATION = 1, POSE = 2 };

// layout of a frame task's spec (int64): first row, row set, whether to zero the drift
// (else it is computed), then the columns of the frame's supporting joints
enum SpecField : Index { SPEC_START = 0, SPEC_MODE = 1, SPEC_ZERO_DRIFT = 2, SPEC_COLS = 3 };

// rows of a frame task's constant geometry geo (5 x 3): the point's offset in the frame,
// the point in the parent joint's frame, then the frame's rotation in the joint's frame
enum GeoRow : Index { GEO_OFFSET = 0, GEO_POINT = 1, GEO_ROTATION = 2 };

// out[o:o+3] = log(R), the rotation vector theta u (theta in [0, pi]) of a 3 x 3 rotation.
void log3(const ConstMatrix& R, const Vector& out, Index o);

// The arguments every frame writer shares: where it writes (A, Q), the world-frame joint
// Jacobians J, the frame's placement (t, R), spec, geo and the parent joint's spatial
// acceleration aj and velocity vj.
struct FrameArgs {
  Matrix A, Q;
  ConstMatrix J;
  ConstVector t;
  ConstMatrix R;
  ConstIndices spec;
  ConstMatrix geo;
  ConstVector aj, vj;
};

// A point's position rows (3 at spec[SPEC_START]): the point p = t + R off, error x - p,
// reference velocity xd and feed-forward xdd (zero unless rates), the drift computed or
// zeroed as spec says.
void point_rows(const FrameArgs& f, const ConstVector& x, const ConstVector& xd,
                const ConstVector& xdd, bool rates);

// One frame's rows at spec[SPEC_START]: position (3 rows), orientation (3) or both (6),
// as spec[SPEC_MODE] says. Position rows: J_lin + J_ang x p on the columns spec[3:]
// (zero elsewhere), error x - p, xd, xdd. Orientation rows: J_ang, error log(R* R^T),
// w, wd.
void frame_rows(const FrameArgs& f, const ConstVector& x, const ConstVector& xd,
                const ConstVector& xdd, const ConstMatrix& Rstar, const ConstVector& w,
                const ConstVector& wd);

// Centre-of-mass rows at s on axes: A = Jcom[axes], error x - com[axes], xd, xdd, drift
// acom[axes] (zeroed if zero_drift).
void com_rows(const Matrix& A, const Matrix& Q, Index s, const ConstMatrix& Jcom,
              const ConstVector& com, const ConstVector& acom, const ConstIndices& axes,
              const ConstVector& x, const ConstVector& xd, const ConstVector& xdd,
              bool zero_drift);

// Posture targets at s: error q_ref[iq] - q[iq], zero reference velocity, feed-forward
// and drift.
void posture_error(const Matrix& Q, Index s, const ConstVector& q, const ConstVector& q_ref,
                   const ConstIndices& iq);

// out[k] = q[iq[k]] (0 where iq[k] < 0).
void actuated_positions(const ConstVector& q, const ConstIndices& iq, const Vector& out);

// Joint-limit activation rows at s, one per actuated joint (columns nb + k); returns the
// number of active rows.
Index limit_activation_rows(const Matrix& A, const Matrix& Q, Index s, Index nb,
                            const ConstVector& qa, const ConstVector& lo,
                            const ConstVector& hi, const ConstVector& width, double kp,
                            double kd);

// Bounds on the actuated joints' accelerations at s (horizon T, step dt; position and/or
// velocity limits).
void acceleration_bounds(const Vector& lower, const Vector& upper, Index s,
                         const ConstVector& qa, const ConstVector& va, const ConstVector& lo,
                         const ConstVector& hi, const ConstVector& vmax, double T, double dt,
                         bool position, bool velocity);

// Bounds on the actuated joints' velocities at s (q + qd T within the position limits,
// |qd| <= vmax).
void velocity_bounds(const Vector& lower, const Vector& upper, Index s, const ConstVector& qa,
                     const ConstVector& lo, const ConstVector& hi, const ConstVector& vmax,
                     double T, bool position, bool velocity);

// A region task's rows at s: A = C Jp, y = psign C p, and the bounds of velocity_bounds
// (accel false) or of acceleration_bounds on y and yd = C Jp v less C drift. y and yd are
// the caller's scratch (C.rows entries each).
void region_rows(const Matrix& A, const Vector& lower, const Vector& upper, Index s,
                 const ConstMatrix& C, const ConstMatrix& Jp, const ConstVector& p,
                 double psign, const ConstVector& v, const ConstVector& drift,
                 const ConstVector& lo, const ConstVector& hi, const Vector& y,
                 const Vector& yd, const ConstVector& vmax, double T, double dt, bool accel);

// A joint-limit bounds task from the state: lim = (lo, hi, vmax) rows (3 x n_a), params =
// (row start, T, dt, position, velocity, acceleration level); qa: scratch (n_a).
void bounds_at(const Vector& lower, const Vector& upper, const ConstVector& q,
               const ConstVector& v, const ConstIndices& iq, const ConstMatrix& lim,
               const ConstVector& params, const Vector& qa);

// A joint-limit activation task from the state: lim = (lo, hi, width) rows (3 x n_a),
// params = (row start, n_base, K_p, K_d); returns the number of active rows.
Index activation_at(const Matrix& A, const Matrix& Q, const ConstVector& q,
                    const ConstIndices& iq, const ConstMatrix& lim, const ConstVector& params,
                    const Vector& qa);

// b = xd* + K e per row.
void velocity_targets(const Vector& b, const ConstMatrix& Q);

// b = xdd* + K_d (xd* - A v) + K_p e - drift per row.
void acceleration_targets(const ConstMatrix& A, const Vector& b, const ConstMatrix& Q,
                          const ConstVector& v);

// Every entry of q and v finite and every unit-norm part of q (unit = [start_0, size_0,
// start_1, size_1, ...]) of norm 1 within tol.
bool state_is_valid(const ConstVector& q, const ConstVector& v, const ConstIndices& unit,
                    double tol);

}  // namespace prioik::rows
