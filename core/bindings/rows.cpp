// prioik._core.rows: the robot row writers' bindings (rows.hpp).
//
// Every array is taken through the buffer protocol as it is (no copy; any strides, as
// pinocchio's column-major matrices come): float64 or int64 as the argument says,
// writable where the writer writes, of the shapes the other arguments imply, and every
// index a writer follows (a row start, the columns of a frame's spec, the entries of
// iq, axes and unit) within the arrays it indexes. Anything else raises
// prioik.formulations.base.CoreInputError naming the array before C++ reads it (None
// in place of an array too). A writer's references (a target, its rates, a target
// rotation, a posture's q_ref) must be finite: a NaN or an infinity there raises
// CoreInputError naming the array and the entry (robots/rows.py names the task). Other
// non-finite values (the state's) are the writers' to propagate (IEEE arithmetic): the
// state and the solvers check them. The GIL is released while a writer runs.
#include "rows_bindings.hpp"

#include <nanobind/nanobind.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>

#include "array_checks.hpp"
#include "prioik/extended_jacobian.hpp"
#include "prioik/rows.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using prioik::InputError;
using namespace prioik::rows;

enum class Kind { Float, Int };

// An array argument as C++ reads it: its data, dimensions and strides (bytes).
struct ArrayInfo {
  void* buf = nullptr;
  int ndim = 0;
  const Py_ssize_t* shape = nullptr;
  const Py_ssize_t* strides = nullptr;
};

// NumPy's array and dtype fields (array_checks.hpp), read directly: a numpy.ndarray
// argument costs a few field reads where the buffer protocol builds a format string per
// call (as much time as the writer's work); register_rows checks the layout on arrays of
// its own and leaves the buffer protocol in place where it does not hold.
using prioik::bindings::kNumpyAligned;
using prioik::bindings::kNumpyWriteable;
using prioik::bindings::NumpyArrayFields;
using prioik::bindings::NumpyDescrFields;

// numpy.ndarray, when its fields are read directly (null: the buffer protocol)
PyTypeObject* numpy_array_type = nullptr;

bool type_char_is(char type, Kind kind) {
  return kind == Kind::Float ? type == 'd'
                             : (type == 'q' || (type == 'l' && sizeof(long) == 8));
}

// The arrays a call reads (buffers taken through the protocol are released when the
// call returns, after the GIL is taken back).
class Buffers {
 public:
  Buffers() = default;
  Buffers(const Buffers&) = delete;
  Buffers& operator=(const Buffers&) = delete;
  ~Buffers() {
    for (int i = 0; i < count_; ++i) PyBuffer_Release(&views_[i]);
  }

  // the array `h` (ndim dimensions, 8-byte items of `kind`), or InputError naming it
  ArrayInfo take(nb::handle h, const char* name, int ndim, Kind kind, bool writable) {
    ArrayInfo a = numpy_array_type != nullptr && PyObject_TypeCheck(h.ptr(), numpy_array_type)
                      ? numpy_fields(h, name, kind, writable)
                      : buffer(h, name, kind, writable);
    if (a.ndim != ndim)
      throw InputError(std::string(name) + " must have " + std::to_string(ndim) +
                       " dimension" + (ndim == 1 ? "" : "s") + ", got " +
                       std::to_string(a.ndim));
    for (int d = 0; d < ndim; ++d)
      if (a.strides[d] % 8 != 0)
        throw InputError(std::string(name) + " has strides that are not whole items");
    return a;
  }

 private:
  static constexpr int kMax = 20;
  Py_buffer views_[kMax];
  int count_ = 0;

  static const char* type_name(Kind kind) { return kind == Kind::Float ? "float64" : "int64"; }

  [[noreturn]] static void not_an_array(nb::handle h, const char* name, Kind kind,
                                        bool writable, bool read_only) {
    throw InputError(std::string(name) + " must be a" + (writable ? " writable " : " ") +
                     type_name(kind) + " numpy array, got " +
                     (read_only ? "a read-only array" : Py_TYPE(h.ptr())->tp_name));
  }

  // the dtype's name (numpy's dtype.name) of an array
  static std::string dtype_name(nb::handle h) {
    nb::object name = h.attr("dtype").attr("name");
    return nb::isinstance<nb::str>(name) ? std::string(nb::borrow<nb::str>(name).c_str())
                                         : std::string("another dtype");
  }

  static ArrayInfo numpy_fields(nb::handle h, const char* name, Kind kind, bool writable) {
    const auto* a = reinterpret_cast<const NumpyArrayFields*>(h.ptr());
    const auto* d = reinterpret_cast<const NumpyDescrFields*>(a->descr);
    if (writable && !(a->flags & kNumpyWriteable)) not_an_array(h, name, kind, true, true);
    if (!type_char_is(d->type, kind) || d->byteorder == '>')
      throw InputError(std::string(name) + " must be " + type_name(kind) + ", got " +
                       dtype_name(h) + (d->byteorder == '>' ? " (big-endian)" : ""));
    if (!(a->flags & kNumpyAligned))
      throw InputError(std::string(name) + " is not aligned (a view of packed bytes)");
    return ArrayInfo{a->data, a->nd, a->dimensions, a->strides};
  }

  ArrayInfo buffer(nb::handle h, const char* name, Kind kind, bool writable) {
    if (count_ == kMax) throw InputError("internal: too many arrays in one call");
    Py_buffer& view = views_[count_];
    const int flags = PyBUF_RECORDS_RO | (writable ? PyBUF_WRITABLE : 0);
    if (!PyObject_CheckBuffer(h.ptr()) || PyObject_GetBuffer(h.ptr(), &view, flags) != 0) {
      PyErr_Clear();
      not_an_array(h, name, kind, writable, writable && PyObject_CheckBuffer(h.ptr()));
    }
    ++count_;
    if (view.itemsize != 8 || !format_is(view.format, kind))
      throw InputError(std::string(name) + " must be " + type_name(kind) + ", got format '" +
                       (view.format ? view.format : "B") + "' of " +
                       std::to_string(view.itemsize) + "-byte items");
    if (reinterpret_cast<std::uintptr_t>(view.buf) % alignof(double) != 0)
      throw InputError(std::string(name) + " is not aligned (a view of packed bytes)");
    return ArrayInfo{view.buf, view.ndim, view.shape, view.strides};
  }

  static bool format_is(const char* format, Kind kind) {
    if (format == nullptr) return false;
    if (*format == '@' || *format == '=' || *format == '<') ++format;
    if (format[0] == '\0' || format[1] != '\0') return false;
    return type_char_is(format[0], kind);
  }
};

std::string shape_error(const char* name, const std::string& want, const ArrayInfo& v) {
  std::string got = "(";
  for (int d = 0; d < v.ndim; ++d) got += (d ? ", " : "") + std::to_string(v.shape[d]);
  return std::string(name) + " must have " + want + ", got shape " + got +
         (v.ndim == 1 ? ",)" : ")");
}

// a vector of `size` entries (-1: any)
template <class T>
VectorView<T> vector(Buffers& bufs, nb::handle h, const char* name, Index size) {
  constexpr bool writable = !std::is_const_v<T>;
  constexpr Kind kind = std::is_same_v<std::remove_const_t<T>, double> ? Kind::Float : Kind::Int;
  const ArrayInfo v = bufs.take(h, name, 1, kind, writable);
  if (size >= 0 && v.shape[0] != size)
    throw InputError(shape_error(name, std::to_string(size) + " entries", v));
  return VectorView<T>{static_cast<T*>(v.buf), static_cast<Index>(v.shape[0]),
                       static_cast<Index>(v.strides[0] / 8)};
}

// a matrix of rows x cols (-1: any)
template <class T>
MatrixView<T> matrix(Buffers& bufs, nb::handle h, const char* name, Index rows, Index cols) {
  constexpr bool writable = !std::is_const_v<T>;
  const ArrayInfo v = bufs.take(h, name, 2, Kind::Float, writable);
  if ((rows >= 0 && v.shape[0] != rows) || (cols >= 0 && v.shape[1] != cols))
    throw InputError(shape_error(
        name, "shape (" + (rows >= 0 ? std::to_string(rows) : std::string("·")) + ", " +
                  (cols >= 0 ? std::to_string(cols) : std::string("·")) + ")", v));
  return MatrixView<T>{static_cast<T*>(v.buf), static_cast<Index>(v.shape[0]),
                       static_cast<Index>(v.shape[1]), static_cast<Index>(v.strides[0] / 8),
                       static_cast<Index>(v.strides[1] / 8)};
}

// `v` (a writer's reference), or InputError naming its first entry that is not finite
template <class View>
View finite(const View& v, const char* name) {
  for (Index k = 0; k < v.size; ++k)
    if (!std::isfinite(v[k]))
      throw InputError(std::string(name) + "[" + std::to_string(k) + "] is not finite (" +
                       (std::isnan(v[k]) ? "nan" : (v[k] > 0 ? "inf" : "-inf")) + ")");
  return v;
}

// the 3 x 3 matrix `m` (a target rotation), or InputError naming its first entry that
// is not finite
ConstMatrix finite_matrix(const ConstMatrix& m, const char* name) {
  for (Index i = 0; i < m.rows; ++i)
    for (Index j = 0; j < m.cols; ++j)
      if (!std::isfinite(m(i, j)))
        throw InputError(std::string(name) + "[" + std::to_string(i) + ", " +
                         std::to_string(j) + "] is not finite (" +
                         (std::isnan(m(i, j)) ? "nan" : (m(i, j) > 0 ? "inf" : "-inf")) +
                         ")");
  return m;
}

// InputError(message()) unless ok (the message is built only for an error)
template <class Message>
void require(bool ok, const Message& message) {
  if (!ok) throw InputError(message());
}

// `count` rows (or columns, entries) from s within an array's `rows`, named
void rows_within(Index s, Index count, Index rows, const char* what, const char* array,
                 const char* unit = "rows") {
  require(s >= 0 && count <= rows && s <= rows - count, [&] {
    return std::string(what) + " (" + std::to_string(count) + " from " + std::to_string(s) +
           ") are outside " + array + "'s " + std::to_string(rows) + " " + unit;
  });
}

// every entry of `idx` from `first` on in [lo, hi)
void indices_within(const ConstIndices& idx, Index first, Index lo, Index hi,
                    const char* name, const char* of) {
  for (Index k = first; k < idx.size; ++k)
    require(idx[k] >= lo && idx[k] < hi, [&] {
      return std::string(name) + "[" + std::to_string(k) + "] = " + std::to_string(idx[k]) +
             " is not an index of " + of + " (" + std::to_string(lo) + " .. " +
             std::to_string(hi - 1) + ")";
    });
}

// the frame writers' shared arguments, checked against each other
FrameArgs frame_args(Buffers& bufs, nb::handle A, nb::handle Q, nb::handle J, nb::handle t,
                     nb::handle R, nb::handle spec, nb::handle geo, nb::handle aj,
                     nb::handle vj, bool position_only) {
  FrameArgs f;
  f.A = matrix<double>(bufs, A, "A", -1, -1);
  f.Q = matrix<double>(bufs, Q, "Q", 6, f.A.rows);
  f.J = matrix<const double>(bufs, J, "J", 6, f.A.cols);
  f.t = vector<const double>(bufs, t, "t", 3);
  f.R = matrix<const double>(bufs, R, "R", 3, 3);
  f.spec = vector<const std::int64_t>(bufs, spec, "spec", -1);
  f.geo = matrix<const double>(bufs, geo, "geo", 5, 3);
  f.aj = vector<const double>(bufs, aj, "aj", 6);
  f.vj = vector<const double>(bufs, vj, "vj", 6);
  require(f.spec.size >= SPEC_COLS, [&] {
    return std::string("spec must hold at least 3 entries (start, mode, zero drift)");
  });
  const Index mode = f.spec[SPEC_MODE];
  require(mode == POSITION || (!position_only && (mode == ORIENTATION || mode == POSE)), [&] {
    return "spec[1] = " + std::to_string(mode) + " is not a row set (" +
           (position_only ? "0: position" : "0: position, 1: orientation, 2: pose") + ")";
  });
  rows_within(f.spec[SPEC_START], mode == POSE ? 6 : 3, f.A.rows, "spec's rows", "A");
  indices_within(f.spec, SPEC_COLS, 0, f.A.cols, "spec", "A's columns");
  return f;
}

void position_rows(nb::handle A, nb::handle Q, nb::handle J, nb::handle t, nb::handle R,
                   nb::handle spec, nb::handle geo, nb::handle aj, nb::handle vj, nb::handle x,
                   nb::handle xd, nb::handle xdd) {
  Buffers bufs;
  const FrameArgs f = frame_args(bufs, A, Q, J, t, R, spec, geo, aj, vj, true);
  const ConstVector xv = finite(vector<const double>(bufs, x, "x", 3), "x");
  const ConstVector xdv = finite(vector<const double>(bufs, xd, "xd", 3), "xd");
  const ConstVector xddv = finite(vector<const double>(bufs, xdd, "xdd", 3), "xdd");
  nb::gil_scoped_release release;
  point_rows(f, xv, xdv, xddv, true);
}

void position_target_rows(nb::handle A, nb::handle Q, nb::handle J, nb::handle t,
                          nb::handle R, nb::handle spec, nb::handle geo, nb::handle aj,
                          nb::handle vj, nb::handle x) {
  Buffers bufs;
  const FrameArgs f = frame_args(bufs, A, Q, J, t, R, spec, geo, aj, vj, true);
  const ConstVector xv = finite(vector<const double>(bufs, x, "x", 3), "x");
  nb::gil_scoped_release release;
  point_rows(f, xv, xv, xv, false);
}

void frame_rows_binding(nb::handle A, nb::handle Q, nb::handle J, nb::handle t, nb::handle R,
                        nb::handle spec, nb::handle geo, nb::handle aj, nb::handle vj,
                        nb::handle x, nb::handle xd, nb::handle xdd, nb::handle Rstar,
                        nb::handle w, nb::handle wd) {
  Buffers bufs;
  const FrameArgs f = frame_args(bufs, A, Q, J, t, R, spec, geo, aj, vj, false);
  const ConstVector xv = finite(vector<const double>(bufs, x, "x", 3), "x");
  const ConstVector xdv = finite(vector<const double>(bufs, xd, "xd", 3), "xd");
  const ConstVector xddv = finite(vector<const double>(bufs, xdd, "xdd", 3), "xdd");
  const ConstMatrix Rs =
      finite_matrix(matrix<const double>(bufs, Rstar, "Rstar", 3, 3), "Rstar");
  const ConstVector wv = finite(vector<const double>(bufs, w, "w", 3), "w");
  const ConstVector wdv = finite(vector<const double>(bufs, wd, "wd", 3), "wd");
  nb::gil_scoped_release release;
  frame_rows(f, xv, xdv, xddv, Rs, wv, wdv);
}

void com_rows_binding(nb::handle A, nb::handle Q, Index s, nb::handle Jcom, nb::handle com,
                      nb::handle acom, nb::handle axes, nb::handle x, nb::handle xd,
                      nb::handle xdd, bool zero_drift) {
  Buffers bufs;
  const Matrix Am = matrix<double>(bufs, A, "A", -1, -1);
  const Matrix Qm = matrix<double>(bufs, Q, "Q", 6, Am.rows);
  const ConstMatrix Jc = matrix<const double>(bufs, Jcom, "Jcom", 3, Am.cols);
  const ConstVector c = vector<const double>(bufs, com, "com", 3);
  const ConstVector ac = vector<const double>(bufs, acom, "acom", 3);
  const ConstIndices ax = vector<const std::int64_t>(bufs, axes, "axes", -1);
  indices_within(ax, 0, 0, 3, "axes", "the world axes");
  rows_within(s, ax.size, Am.rows, "the task's rows", "A");
  const ConstVector xv = finite(vector<const double>(bufs, x, "x", ax.size), "x");
  const ConstVector xdv = finite(vector<const double>(bufs, xd, "xd", ax.size), "xd");
  const ConstVector xddv = finite(vector<const double>(bufs, xdd, "xdd", ax.size), "xdd");
  nb::gil_scoped_release release;
  com_rows(Am, Qm, s, Jc, c, ac, ax, xv, xdv, xddv, zero_drift);
}

void posture_error_binding(nb::handle Q, Index s, nb::handle q, nb::handle q_ref,
                           nb::handle iq) {
  Buffers bufs;
  const Matrix Qm = matrix<double>(bufs, Q, "Q", 6, -1);
  const ConstVector qv = vector<const double>(bufs, q, "q", -1);
  const ConstVector qr = finite(vector<const double>(bufs, q_ref, "q_ref", qv.size), "q_ref");
  const ConstIndices idx = vector<const std::int64_t>(bufs, iq, "iq", -1);
  indices_within(idx, 0, 0, qv.size, "iq", "q");
  rows_within(s, idx.size, Qm.cols, "the task's rows", "Q");
  nb::gil_scoped_release release;
  posture_error(Qm, s, qv, qr, idx);
}

void actuated_positions_binding(nb::handle q, nb::handle iq, nb::handle out) {
  Buffers bufs;
  const ConstVector qv = vector<const double>(bufs, q, "q", -1);
  const ConstIndices idx = vector<const std::int64_t>(bufs, iq, "iq", -1);
  indices_within(idx, 0, -(std::int64_t{1} << 62), qv.size, "iq", "q");
  const Vector o = vector<double>(bufs, out, "out", idx.size);
  nb::gil_scoped_release release;
  actuated_positions(qv, idx, o);
}

// lo, hi and a third per-joint array of na entries each
struct JointArrays {
  ConstVector lo, hi, third;
};

JointArrays joint_arrays(Buffers& bufs, nb::handle lo, nb::handle hi, nb::handle third,
                         const char* third_name, Index na) {
  return JointArrays{vector<const double>(bufs, lo, "lo", na),
                     vector<const double>(bufs, hi, "hi", na),
                     vector<const double>(bufs, third, third_name, na)};
}

Index limit_activation_rows_binding(nb::handle A, nb::handle Q, Index s, Index nb_,
                                    nb::handle qa, nb::handle lo, nb::handle hi,
                                    nb::handle width, double kp, double kd) {
  Buffers bufs;
  const Matrix Am = matrix<double>(bufs, A, "A", -1, -1);
  const Matrix Qm = matrix<double>(bufs, Q, "Q", 6, Am.rows);
  const ConstVector q = vector<const double>(bufs, qa, "qa", -1);
  const JointArrays j = joint_arrays(bufs, lo, hi, width, "width", q.size);
  rows_within(s, q.size, Am.rows, "the task's rows", "A");
  rows_within(nb_, q.size, Am.cols, "the joints' columns", "A", "columns");
  nb::gil_scoped_release release;
  return limit_activation_rows(Am, Qm, s, nb_, q, j.lo, j.hi, j.third, kp, kd);
}

// lower and upper of equal sizes, with rows s .. s + count
std::pair<Vector, Vector> bound_arrays(Buffers& bufs, nb::handle lower, nb::handle upper,
                                       Index s, Index count) {
  const Vector lo = vector<double>(bufs, lower, "lower", -1);
  const Vector hi = vector<double>(bufs, upper, "upper", lo.size);
  rows_within(s, count, lo.size, "the task's rows", "lower");
  return {lo, hi};
}

void acceleration_bounds_binding(nb::handle lower, nb::handle upper, Index s, nb::handle qa,
                                 nb::handle va, nb::handle lo, nb::handle hi, nb::handle vmax,
                                 double T, double dt, bool position, bool velocity) {
  Buffers bufs;
  const ConstVector q = vector<const double>(bufs, qa, "qa", -1);
  const ConstVector v = vector<const double>(bufs, va, "va", q.size);
  const JointArrays j = joint_arrays(bufs, lo, hi, vmax, "vmax", q.size);
  const auto [l, u] = bound_arrays(bufs, lower, upper, s, q.size);
  nb::gil_scoped_release release;
  acceleration_bounds(l, u, s, q, v, j.lo, j.hi, j.third, T, dt, position, velocity);
}

void velocity_bounds_binding(nb::handle lower, nb::handle upper, Index s, nb::handle qa,
                             nb::handle lo, nb::handle hi, nb::handle vmax, double T,
                             bool position, bool velocity) {
  Buffers bufs;
  const ConstVector q = vector<const double>(bufs, qa, "qa", -1);
  const JointArrays j = joint_arrays(bufs, lo, hi, vmax, "vmax", q.size);
  const auto [l, u] = bound_arrays(bufs, lower, upper, s, q.size);
  nb::gil_scoped_release release;
  velocity_bounds(l, u, s, q, j.lo, j.hi, j.third, T, position, velocity);
}

void region_rows_binding(nb::handle A, nb::handle lower, nb::handle upper, Index s,
                         nb::handle C, nb::handle Jp, nb::handle p, double psign, nb::handle v,
                         nb::handle drift, nb::handle lo, nb::handle hi, nb::handle y,
                         nb::handle yd, nb::handle vmax, double T, double dt, bool accel) {
  Buffers bufs;
  const Matrix Am = matrix<double>(bufs, A, "A", -1, -1);
  const ConstMatrix Cm = matrix<const double>(bufs, C, "C", -1, 3);
  const Index k = Cm.rows;
  const auto [l, u] = bound_arrays(bufs, lower, upper, s, k);
  rows_within(s, k, Am.rows, "the task's rows", "A");
  const ConstMatrix J = matrix<const double>(bufs, Jp, "Jp", 3, Am.cols);
  const ConstVector pv = vector<const double>(bufs, p, "p", 3);
  const ConstVector vv = vector<const double>(bufs, v, "v", Am.cols);
  const ConstVector dv = vector<const double>(bufs, drift, "drift", 3);
  const JointArrays j = joint_arrays(bufs, lo, hi, vmax, "vmax", k);
  const Vector yv = vector<double>(bufs, y, "y", k);
  const Vector ydv = vector<double>(bufs, yd, "yd", k);
  nb::gil_scoped_release release;
  region_rows(Am, l, u, s, Cm, J, pv, psign, vv, dv, j.lo, j.hi, yv, ydv, j.third, T, dt,
              accel);
}

// params[0] (a row start given as a float) as an index
Index row_start(const ConstVector& params, const char* name) {
  const double s = params[0];
  const bool whole = s >= 0.0 && s < 9.0e15 && s == static_cast<double>(static_cast<Index>(s));
  require(whole, [&] {
    return std::string(name) + "[0] (the first row) must be a whole number >= 0";
  });
  return static_cast<Index>(s);
}

void bounds_at_binding(nb::handle lower, nb::handle upper, nb::handle q, nb::handle v,
                       nb::handle iq, nb::handle lim, nb::handle params, nb::handle qa) {
  Buffers bufs;
  const ConstVector qv = vector<const double>(bufs, q, "q", -1);
  const ConstIndices idx = vector<const std::int64_t>(bufs, iq, "iq", -1);
  const Index na = idx.size;
  indices_within(idx, 0, -(std::int64_t{1} << 62), qv.size, "iq", "q");
  const ConstVector vv = vector<const double>(bufs, v, "v", -1);
  require(vv.size >= na, [&] {
    return "v has " + std::to_string(vv.size) + " entries, fewer than the " +
           std::to_string(na) + " actuated joints";
  });
  const ConstMatrix L = matrix<const double>(bufs, lim, "lim", 3, na);
  const ConstVector P = vector<const double>(bufs, params, "params", 6);
  const Vector scratch = vector<double>(bufs, qa, "qa", na);
  const auto [l, u] = bound_arrays(bufs, lower, upper, row_start(P, "params"), na);
  nb::gil_scoped_release release;
  bounds_at(l, u, qv, vv, idx, L, P, scratch);
}

Index activation_at_binding(nb::handle A, nb::handle Q, nb::handle q, nb::handle iq,
                            nb::handle lim, nb::handle params, nb::handle qa) {
  Buffers bufs;
  const Matrix Am = matrix<double>(bufs, A, "A", -1, -1);
  const Matrix Qm = matrix<double>(bufs, Q, "Q", 6, Am.rows);
  const ConstVector qv = vector<const double>(bufs, q, "q", -1);
  const ConstIndices idx = vector<const std::int64_t>(bufs, iq, "iq", -1);
  const Index na = idx.size;
  indices_within(idx, 0, -(std::int64_t{1} << 62), qv.size, "iq", "q");
  const ConstMatrix L = matrix<const double>(bufs, lim, "lim", 3, na);
  const ConstVector P = vector<const double>(bufs, params, "params", 4);
  const Vector scratch = vector<double>(bufs, qa, "qa", na);
  rows_within(row_start(P, "params"), na, Am.rows, "the task's rows", "A");
  const double nb_ = P[1];
  const bool whole =
      nb_ >= 0.0 && nb_ < 9.0e15 && nb_ == static_cast<double>(static_cast<Index>(nb_));
  require(whole && static_cast<Index>(nb_) + na <= Am.cols, [&] {
    return "params[1] (n_base) must be a whole number with n_base + " + std::to_string(na) +
           " <= A's " + std::to_string(Am.cols) + " columns";
  });
  nb::gil_scoped_release release;
  return activation_at(Am, Qm, qv, idx, L, P, scratch);
}

void velocity_targets_binding(nb::handle b, nb::handle Q) {
  Buffers bufs;
  const Vector bv = vector<double>(bufs, b, "b", -1);
  const ConstMatrix Qm = matrix<const double>(bufs, Q, "Q", 6, bv.size);
  nb::gil_scoped_release release;
  velocity_targets(bv, Qm);
}

void acceleration_targets_binding(nb::handle A, nb::handle b, nb::handle Q, nb::handle v) {
  Buffers bufs;
  const ConstMatrix Am = matrix<const double>(bufs, A, "A", -1, -1);
  const Vector bv = vector<double>(bufs, b, "b", Am.rows);
  const ConstMatrix Qm = matrix<const double>(bufs, Q, "Q", 6, Am.rows);
  const ConstVector vv = vector<const double>(bufs, v, "v", Am.cols);
  nb::gil_scoped_release release;
  acceleration_targets(Am, bv, Qm, vv);
}

bool state_is_valid_binding(nb::handle q, nb::handle v, nb::handle unit, double tol) {
  Buffers bufs;
  const ConstVector qv = vector<const double>(bufs, q, "q", -1);
  const ConstVector vv = vector<const double>(bufs, v, "v", -1);
  const ConstIndices u = vector<const std::int64_t>(bufs, unit, "unit", -1);
  require(u.size % 2 == 0, [&] {
    return "unit must hold (start, size) pairs, got " + std::to_string(u.size) + " entries";
  });
  for (Index p = 0; p < u.size; p += 2)
    require(u[p] >= 0 && u[p + 1] >= 0 && u[p] <= qv.size && u[p + 1] <= qv.size - u[p], [&] {
      return "unit's part " + std::to_string(p / 2) + " (" + std::to_string(u[p]) + ", " +
             std::to_string(u[p + 1]) + ") is not within q's " + std::to_string(qv.size) +
             " entries";
    });
  nb::gil_scoped_release release;
  return state_is_valid(qv, vv, u, tol);
}

void log3_binding(nb::handle R, nb::handle out, Index o) {
  Buffers bufs;
  const ConstMatrix Rm = matrix<const double>(bufs, R, "R", 3, 3);
  const Vector ov = vector<double>(bufs, out, "out", -1);
  rows_within(o, 3, ov.size, "entries", "out", "entries");
  nb::gil_scoped_release release;
  log3(Rm, ov, o);
}

// Whether NumpyArrayFields reads numpy's arrays as they are (checked on arrays made
// here: a float64 matrix, an int64 vector and a read-only column view).
bool numpy_layout_holds(nb::handle ndarray_type) {
  nb::module_ np = nb::module_::import_("numpy");
  nb::object m = np.attr("zeros")(nb::make_tuple(2, 3));
  nb::object v = np.attr("arange")(5, "dtype"_a = "int64");
  nb::object c = m[nb::make_tuple(nb::slice(nb::none(), nb::none(), nb::none()), 1)];
  c.attr("setflags")("write"_a = false);
  auto address = [](nb::handle o) {
    return nb::cast<std::uintptr_t>(o.attr("__array_interface__")["data"][0]);
  };
  auto fields = [](nb::handle o) { return reinterpret_cast<const NumpyArrayFields*>(o.ptr()); };
  auto type = [&](nb::handle o) {
    return reinterpret_cast<const NumpyDescrFields*>(fields(o)->descr)->type;
  };
  if (!PyObject_TypeCheck(m.ptr(), reinterpret_cast<PyTypeObject*>(ndarray_type.ptr())))
    return false;
  const NumpyArrayFields* fm = fields(m);
  const NumpyArrayFields* fv = fields(v);
  const NumpyArrayFields* fc = fields(c);
  return fm->nd == 2 && fm->dimensions[0] == 2 && fm->dimensions[1] == 3 &&
         fm->strides[0] == 24 && fm->strides[1] == 8 &&
         reinterpret_cast<std::uintptr_t>(fm->data) == address(m) &&
         (fm->flags & kNumpyWriteable) && (fm->flags & kNumpyAligned) &&
         type_char_is(type(m), Kind::Float) && fv->nd == 1 && fv->dimensions[0] == 5 &&
         type_char_is(type(v), Kind::Int) && !type_char_is(type(v), Kind::Float) &&
         fc->nd == 1 && fc->strides[0] == 24 && !(fc->flags & kNumpyWriteable) &&
         reinterpret_cast<std::uintptr_t>(fc->data) == address(m) + 8;
}

}  // namespace

void register_rows(nb::module_& parent) {
  nb::object ndarray_type = nb::module_::import_("numpy").attr("ndarray");
  if (numpy_layout_holds(ndarray_type)) {
    numpy_array_type = reinterpret_cast<PyTypeObject*>(ndarray_type.ptr());
    ndarray_type.inc_ref();     // kept for the process's life
  }
  // an array argument: None is let through to the binding, which names it
  auto a = [](const char* name) { return nb::arg(name).none(); };
  nb::module_ m = parent.def_submodule(
      "rows", "The robot row writers (prioik.robots.rows): one task's rows of a stack "
              "from views of a pinocchio Data, written into the caller's arrays.");
  m.attr("READS_NUMPY_FIELDS") = numpy_array_type != nullptr;
  m.attr("ERROR") = Index{ERROR};
  m.attr("VELOCITY_REF") = Index{VELOCITY_REF};
  m.attr("FEEDFORWARD") = Index{FEEDFORWARD};
  m.attr("DRIFT") = Index{DRIFT};
  m.attr("KP") = Index{KP};
  m.attr("KD") = Index{KD};
  m.attr("POSITION") = Index{POSITION};
  m.attr("ORIENTATION") = Index{ORIENTATION};
  m.attr("POSE") = Index{POSE};

  m.def("log3", &log3_binding, a("R"), a("out"), nb::arg("o"),
        "out[o:o+3] = log(R), the rotation vector (theta in [0, pi]) of a 3 x 3 rotation.");
  m.def("position_rows", &position_rows, a("A"), a("Q"), a("J"),
        a("t"), a("R"), a("spec"), a("geo"), a("aj"),
        a("vj"), a("x"), a("xd"), a("xdd"),
        "A point's position rows (3 at spec[0]; spec[1] must be POSITION): p = t + R off, "
        "error x - p, xd, xdd; the drift computed from aj, vj or zeroed (spec[2]).");
  m.def("position_target_rows", &position_target_rows, a("A"), a("Q"),
        a("J"), a("t"), a("R"), a("spec"), a("geo"),
        a("aj"), a("vj"), a("x"),
        "position_rows with zero reference velocity and feed-forward.");
  m.def("frame_rows", &frame_rows_binding, a("A"), a("Q"), a("J"),
        a("t"), a("R"), a("spec"), a("geo"), a("aj"),
        a("vj"), a("x"), a("xd"), a("xdd"), a("Rstar"),
        a("w"), a("wd"),
        "One frame's rows at spec[0]: position (3), orientation (3, error log(R* R^T)) or "
        "both (6) as spec[1] says, on the columns spec[3:]; drift computed or zeroed.");
  m.def("com_rows", &com_rows_binding, a("A"), a("Q"), nb::arg("s"),
        a("Jcom"), a("com"), a("acom"), a("axes"), a("x"),
        a("xd"), a("xdd"), nb::arg("zero_drift"),
        "Centre-of-mass rows at s on axes: Jcom[axes], error x - com[axes], xd, xdd, "
        "drift acom[axes] (or 0).");
  m.def("posture_error", &posture_error_binding, a("Q"), nb::arg("s"), a("q"),
        a("q_ref"), a("iq"),
        "Posture targets at s: error q_ref[iq] - q[iq]; zero xd, xdd and drift.");
  m.def("actuated_positions", &actuated_positions_binding, a("q"), a("iq"),
        a("out"), "out[k] = q[iq[k]] (0 where iq[k] < 0).");
  m.def("limit_activation_rows", &limit_activation_rows_binding, a("A"), a("Q"),
        nb::arg("s"), nb::arg("nb"), a("qa"), a("lo"), a("hi"),
        a("width"), nb::arg("kp"), nb::arg("kd"),
        "Joint-limit activation rows at s (columns nb + k); returns the active rows' count.");
  m.def("acceleration_bounds", &acceleration_bounds_binding, a("lower"),
        a("upper"), nb::arg("s"), a("qa"), a("va"), a("lo"),
        a("hi"), a("vmax"), nb::arg("T"), nb::arg("dt"), nb::arg("position"),
        nb::arg("velocity"), "Bounds on the actuated joints' accelerations at s.");
  m.def("velocity_bounds", &velocity_bounds_binding, a("lower"), a("upper"),
        nb::arg("s"), a("qa"), a("lo"), a("hi"), a("vmax"),
        nb::arg("T"), nb::arg("position"), nb::arg("velocity"),
        "Bounds on the actuated joints' velocities at s.");
  m.def("region_rows", &region_rows_binding, a("A"), a("lower"), a("upper"),
        nb::arg("s"), a("C"), a("Jp"), a("p"), nb::arg("psign"),
        a("v"), a("drift"), a("lo"), a("hi"), a("y"),
        a("yd"), a("vmax"), nb::arg("T"), nb::arg("dt"), nb::arg("accel"),
        "A region task's rows at s: A = C Jp and the bounds on C Jp qd or C Jp qdd.");
  m.def("bounds_at", &bounds_at_binding, a("lower"), a("upper"), a("q"),
        a("v"), a("iq"), a("lim"), a("params"), a("qa"),
        "A joint-limit bounds task from the state (lim: lo, hi, vmax; params: start, T, "
        "dt, position, velocity, acceleration level).");
  m.def("activation_at", &activation_at_binding, a("A"), a("Q"), a("q"),
        a("iq"), a("lim"), a("params"), a("qa"),
        "A joint-limit activation task from the state (lim: lo, hi, widths; params: "
        "start, n_base, K_p, K_d); returns the active rows' count.");
  m.def("velocity_targets", &velocity_targets_binding, a("b"), a("Q"),
        "b = xd* + K e per row.");
  m.def("acceleration_targets", &acceleration_targets_binding, a("A"), a("b"),
        a("Q"), a("v"), "b = xdd* + K_d (xd* - A v) + K_p e - drift per row.");
  m.def("state_is_valid", &state_is_valid_binding, a("q"), a("v"),
        a("unit"), nb::arg("tol"),
        "Every entry of q and v finite and every unit-norm part of q of norm 1 within tol.");
}
