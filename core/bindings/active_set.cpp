// prioik._core.ActiveSetSolver: the hierarchical active set's bindings. Every entry
// point checks its arrays (dtype float64, shape, C-contiguous, not empty) and a solve that
// refused the values names the one it cannot read (non-finite A or √w, √w ≤ 0, a NaN
// bound): prioik's CoreInputError naming the array and the entry (module.cpp translates
// prioik::InputError). A second thread in a solve raises ConcurrentUseError.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include "array_checks.hpp"
#include "prioik/active_set.hpp"
#include "prioik/certificate.hpp"
#include "prioik/extended_jacobian.hpp"
#include "array_checks.hpp"

namespace nb = nanobind;

namespace {

using prioik::ActiveSetSolver;
using I64 = std::int64_t;

[[noreturn]] void raise_input_error(const std::string& message) {
    throw prioik::InputError(message);
}

using AnyArray = nb::ndarray<nb::ro, nb::device::cpu>;

/// InputError naming `what` unless the array of ndim_got extents extent(d) has shape
/// (rows,) or (rows, cols) when cols ≥ 0, is not empty and is C-contiguous
/// (steps(d, e): whether its stride along d is e elements).
template <class Extent, class Steps>
void check_layout(const std::string& what, I64 ndim_got, Extent extent, Steps steps, I64 rows,
                  I64 cols) {
    auto shape_text = [&] {
        std::string out = "(";
        for (I64 i = 0; i < ndim_got; ++i)
            out += (i ? ", " : "") + std::to_string(extent(i));
        return out + (ndim_got == 1 ? ",)" : ")");
    };
    const I64 ndim = cols < 0 ? 1 : 2;
    for (I64 d = 0; d < ndim_got; ++d)
        if (extent(d) == 0) raise_input_error(what + " is empty (shape " + shape_text() + ")");
    const bool wrong = ndim_got != ndim || extent(0) != rows || (ndim == 2 && extent(1) != cols);
    if (wrong)
        raise_input_error(what + " must have shape (" + std::to_string(rows) +
                          (ndim == 2 ? ", " + std::to_string(cols) + ")" : ",)") + ", got " +
                          shape_text());
    I64 expect = 1;
    for (I64 d = ndim - 1; d >= 0; --d) {
        if (extent(d) > 1 && !steps(d, expect))
            raise_input_error(what + " must be C-contiguous (a view with strides is not "
                              "taken: pass np.ascontiguousarray of it)");
        expect *= extent(d);
    }
}

/// Whether a buffer's format is a float64 in the machine's byte order ("d", "@d", "=d",
/// or "<d"/">d" naming that order).
bool native_float64(const Py_buffer& v) {
    if (v.itemsize != 8 || v.format == nullptr) return false;
    const char* f = v.format;
    constexpr char own_order = PY_LITTLE_ENDIAN ? '<' : '>';
    if (*f == '@' || *f == '=' || *f == own_order) ++f;
    return f[0] == 'd' && f[1] == '\0';
}

/// The leading fields of numpy's array object (array_checks.hpp)
using prioik::bindings::NumpyArrayFields;
using prioik::bindings::NumpyHandles;

/// One input array: an exact numpy.ndarray of float64 read from its fields (a solve's
/// five arrays then cost no Python call), another buffer exporter through the buffer
/// protocol (held until the call returns), anything else through nanobind's ndarray
/// (DLPack). The caller's references keep the arrays alive for the call.
class InputArray {
public:
    InputArray() = default;
    InputArray(const InputArray&) = delete;
    InputArray& operator=(const InputArray&) = delete;
    ~InputArray() {
        if (held_) PyBuffer_Release(&view_);
    }

    /// The array `name` as float64, C-contiguous, of shape (rows,) or (rows, cols) when
    /// cols ≥ 0, not empty; else InputError naming it (the extended Jacobian's wording).
    const double* read(nb::handle h, const char* name, I64 rows, I64 cols) {
        const std::string what(name);
        const NumpyHandles& numpy = NumpyHandles::get();
        if (Py_TYPE(h.ptr()) == numpy.ndarray) {
            const auto* a = reinterpret_cast<const NumpyArrayFields*>(h.ptr());
            if (a->descr == numpy.float64) {
                check_layout(
                    what, a->nd, [&](I64 d) { return static_cast<I64>(a->dimensions[d]); },
                    [&](I64 d, I64 e) {
                        return a->strides[d] == e * static_cast<I64>(sizeof(double));
                    },
                    rows, cols);
                prioik::bindings::require_aligned<double>(a->data, name);
                return reinterpret_cast<const double*>(a->data);
            }
        }
        if (PyObject_CheckBuffer(h.ptr())) {
            if (PyObject_GetBuffer(h.ptr(), &view_, PyBUF_RECORDS_RO) == 0) {
                held_ = true;
                if (!native_float64(view_)) raise_input_error(what + " must be float64");
                check_layout(
                    what, view_.ndim, [&](I64 d) { return static_cast<I64>(view_.shape[d]); },
                    [&](I64 d, I64 e) { return view_.strides[d] == e * view_.itemsize; },
                    rows, cols);
                prioik::bindings::require_aligned<double>(view_.buf, name);
                return static_cast<const double*>(view_.buf);
            }
            PyErr_Clear();    // a buffer it cannot export as strided: read it below
        }
        AnyArray a;
        if (!nb::try_cast(h, a, false))
            raise_input_error(what + " must be a float64 numpy array, got " +
                              nb::cast<std::string>(nb::handle(reinterpret_cast<PyObject*>(
                                  Py_TYPE(h.ptr()))).attr("__name__")));
        if (a.dtype() != nb::dtype<double>()) raise_input_error(what + " must be float64");
        check_layout(
            what, static_cast<I64>(a.ndim()), [&](I64 d) { return static_cast<I64>(a.shape(d)); },
            [&](I64 d, I64 e) { return a.stride(d) == e; }, rows, cols);
        prioik::bindings::require_aligned<double>(a.data(), name);
        return static_cast<const double*>(a.data());
    }

private:
    Py_buffer view_{};
    bool held_ = false;
};

/// The five arrays of a stack, checked (dtypes, shapes, contiguity, not empty) and held
/// for the call.
struct Inputs {
    const double *A = nullptr, *b = nullptr, *lower = nullptr, *upper = nullptr, *sw = nullptr;

    Inputs(const prioik::ActiveSetLayout& layout, nb::handle A_, nb::handle b_, nb::handle lower_,
           nb::handle upper_, nb::handle sw_) {
        I64 M = layout.M, n = layout.n;
        A = arrays_[0].read(A_, "A", M, n);
        b = arrays_[1].read(b_, "b", M, -1);
        lower = arrays_[2].read(lower_, "lower", M, -1);
        upper = arrays_[3].read(upper_, "upper", M, -1);
        sw = arrays_[4].read(sw_, "sqrt_weight", M, -1);
    }

private:
    InputArray arrays_[5];
};

/// After a solve that refused the values (SolveCode::not_solved): the first value the
/// solver cannot read, named (a non-finite entry of A, a √w not finite and > 0, a NaN
/// bound, a non-finite equality target). Returns when none is (an interval the layer
/// above names, or a level of extreme scale it equilibrates). The solve's own pass finds
/// them: a valid stack pays no second pass.
void name_refused_value(const prioik::ActiveSetLayout& layout, const Inputs& in) {
    I64 M = layout.M, n = layout.n;
    auto at = [](I64 j) { return "[" + std::to_string(j) + "]"; };
    for (I64 j = 0; j < M; ++j) {
        for (I64 c = 0; c < n; ++c)
            if (!std::isfinite(in.A[j * n + c]))
                raise_input_error("A[" + std::to_string(j) + ", " + std::to_string(c) +
                                  "] is not finite");
        if (!(in.sw[j] > 0.0 && std::isfinite(in.sw[j])))
            raise_input_error("sqrt_weight" + at(j) + " must be finite and > 0");
        if (std::isnan(in.lower[j])) raise_input_error("lower" + at(j) + " is NaN");
        if (std::isnan(in.upper[j])) raise_input_error("upper" + at(j) + " is NaN");
        if (layout.row_eq[j] && !std::isfinite(in.b[j]))
            raise_input_error("b" + at(j) + " is not finite (an equality row's target)");
    }
}

template <class T>
nb::ndarray<nb::numpy, T> view(std::vector<T>& v, nb::handle owner) {
    size_t shape[1] = {v.size()};
    return nb::ndarray<nb::numpy, T>(v.data(), 1, shape, owner);
}

/// The length of ActiveSetSolver.snapshot's array: x (n), then res, w2, ranks, over (k
/// each) and iterations (k + 1).
I64 snapshot_size(const ActiveSetSolver& s) { return s.layout().n + 5 * s.layout().k + 1; }

/// The data of `out`, a writable float64 array of `size` (an exact numpy array read from
/// its fields, as InputArray; anything else through array_checks.hpp's `output`).
double* snapshot_target(nb::handle out, I64 size) {
    const NumpyHandles& numpy = NumpyHandles::get();
    if (Py_TYPE(out.ptr()) == numpy.ndarray) {
        const auto* a = reinterpret_cast<const NumpyArrayFields*>(out.ptr());
        constexpr int writeable = 0x0400;    // NPY_ARRAY_WRITEABLE (numpy/ndarraytypes.h)
        if (a->descr == numpy.float64 && a->nd == 1 && a->dimensions[0] == size &&
            a->strides[0] == static_cast<Py_ssize_t>(sizeof(double)) && (a->flags & writeable))
            return reinterpret_cast<double*>(a->data);
    }
    return prioik::bindings::output<double>(out, "out", {size});
}

/// The last solve's values copied into `out` (float64, snapshot_size): one copy a Python
/// Solution keeps, the integers as doubles (exact below 2^53).
void copy_snapshot(const ActiveSetSolver& s, nb::handle out) {
    const I64 k = s.layout().k;
    double* to = snapshot_target(out, snapshot_size(s));
    const prioik::ActiveSetResult& r = s.result();
    to = std::copy(r.x.begin(), r.x.end(), to);
    to = std::copy(r.res.begin(), r.res.begin() + k, to);
    to = std::copy(r.w2.begin(), r.w2.begin() + k, to);
    to = std::copy(r.ranks.begin(), r.ranks.begin() + k, to);
    to = std::copy(r.over.begin(), r.over.begin() + k, to);
    std::copy(r.iterations.begin(), r.iterations.begin() + k + 1, to);
}

/// A property reading one of the result's arrays as a numpy view (owned by the solver).
template <class T>
auto result_view(std::vector<T> prioik::ActiveSetResult::*part) {
    return [part](nb::handle h) { return view(nb::cast<ActiveSetSolver&>(h).result().*part, h); };
}

/// A property reading one of the certificate's per-level arrays as a numpy view.
template <class T>
auto certificate_view(std::vector<T> prioik::CertificateResult::*part) {
    return [part](nb::handle h) {
        auto& c = nb::cast<prioik::Certificate&>(h);
        return view(const_cast<prioik::CertificateResult&>(c.result()).*part, h);
    };
}

/// The layout of a prepared solver's constructor arguments (shared by both classes).
prioik::ActiveSetLayout make_layout(I64 n, const std::int64_t* starts, size_t k1,
                                    const std::int8_t* row_eq, size_t M) {
    prioik::ActiveSetLayout layout;
    layout.n = n;
    layout.k = static_cast<I64>(k1) - 1;
    layout.M = static_cast<I64>(M);
    layout.starts.assign(starts, starts + k1);
    layout.row_eq.assign(row_eq, row_eq + M);
    return layout;
}

/// Every value the certificate reads is valid (the stack's boundary check, on the
/// arrays): else InputError naming the first that is not.
void check_certificate_values(const prioik::ActiveSetLayout& layout, const Inputs& in) {
    name_refused_value(layout, in);
    for (I64 j = 0; j < layout.M; ++j)
        if (!layout.row_eq[j] && !(in.lower[j] <= in.upper[j]))
            raise_input_error("lower[" + std::to_string(j) + "] > upper[" + std::to_string(j) +
                              "] (an empty interval)");
}

void bind_certificate(nb::module_& m) {
    using Int8In = nb::ndarray<const std::int8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
    using IndexIn = nb::ndarray<const std::int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
    using prioik::Certificate;
    using prioik::CertificateResult;
    nb::class_<Certificate>(m, "Certificate",
                            "The lexicographic certificate prepared for one layout "
                            "(core/include/prioik/certificate.hpp; hierarchy."
                            "check_lexicographic's verdict); one thread at a time.")
        .def(
            "__init__",
            [](Certificate* self, I64 n, IndexIn starts, Int8In row_eq, double tol,
               double rcond) {
                if (starts.shape(0) < 2) raise_input_error("starts must hold k + 1 >= 2 offsets");
                auto layout = make_layout(n, starts.data(), starts.shape(0), row_eq.data(),
                                          row_eq.shape(0));
                try {
                    new (self) Certificate(std::move(layout), prioik::CertificateOptions{tol, rcond});
                } catch (const std::invalid_argument& e) {
                    raise_input_error(e.what());
                }
            },
            nb::arg("n"), nb::arg("starts"), nb::arg("row_eq"), nb::arg("tol") = 1e-8,
            nb::arg("rcond") = 1e-9)
        .def(
            "check",
            [](Certificate& c, nb::handle A, nb::handle b, nb::handle lower, nb::handle upper,
               nb::handle sw, nb::handle x, bool minimum_norm) {
                Inputs in(c.layout(), A, b, lower, upper, sw);
                InputArray x_array;
                const double* xp = x_array.read(x, "x", c.layout().n, -1);
                check_certificate_values(c.layout(), in);
                nb::gil_scoped_release release;
                return static_cast<int>(
                    c.check(in.A, in.b, in.lower, in.upper, in.sw, xp, minimum_norm));
            },
            nb::arg("A"), nb::arg("b"), nb::arg("lower"), nb::arg("upper"),
            nb::arg("sqrt_weight"), nb::arg("x"), nb::arg("minimum_norm") = false,
            "The verdict on x (1: in the properties; 0: a level of extreme scale, not "
            "checked here). A value it cannot read raises CoreInputError naming it.")
        .def_prop_ro("ok", [](const Certificate& c) { return c.result().ok; })
        .def_prop_ro("failing_level", [](const Certificate& c) { return c.result().failing_level; },
                     "the first failing level (k: the tie-break), -1 when none")
        .def_prop_ro("band_rows_fixed", [](const Certificate& c) { return c.result().band_rows_fixed; })
        .def_prop_ro("snapped_rows", [](const Certificate& c) { return c.result().snapped_rows; })
        .def_prop_ro("residual", certificate_view(&CertificateResult::residual), "k + 1")
        .def_prop_ro("projected_gradient",
                     certificate_view(&CertificateResult::projected_gradient), "k + 1")
        .def_prop_ro("scale", certificate_view(&CertificateResult::scale), "k + 1")
        .def_prop_ro("value_gap", certificate_view(&CertificateResult::value_gap), "k + 1")
        .def_prop_ro("level_ok", certificate_view(&CertificateResult::level_ok), "k + 1")
        .def_prop_ro("ambiguous", certificate_view(&CertificateResult::ambiguous), "k + 1");
}

}  // namespace

void bind_active_set(nb::module_& m) {
    using Int8In = nb::ndarray<const std::int8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
    using IndexIn = nb::ndarray<const std::int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
    nb::dict codes;
    codes["NOT_SOLVED"] = static_cast<int>(prioik::SolveCode::not_solved);
    codes["SOLVED_CLEAN"] = static_cast<int>(prioik::SolveCode::clean);
    codes["SOLVED_INFEASIBLE"] = static_cast<int>(prioik::SolveCode::infeasible);
    codes["SOLVED_OTHER"] = static_cast<int>(prioik::SolveCode::other);
    codes["NOT_TRIED"] = static_cast<int>(prioik::SolveCode::not_tried);
    codes["FLAG_OK"] = static_cast<int>(prioik::FLAG_OK);
    codes["FLAG_ITERATION_CAP"] = static_cast<int>(prioik::FLAG_ITERATION_CAP);
    codes["FLAG_AMBIGUOUS_PATH"] = static_cast<int>(prioik::FLAG_AMBIGUOUS_PATH);
    codes["FLAG_NEAR_RELEASE"] = static_cast<int>(prioik::FLAG_NEAR_RELEASE);
    codes["FLAG_HELD_OFF_BOUND"] = static_cast<int>(prioik::FLAG_HELD_OFF_BOUND);
    codes["FLAG_NEAR_AMBIGUOUS"] = static_cast<int>(prioik::FLAG_NEAR_AMBIGUOUS);
    codes["FLAG_STALLED"] = static_cast<int>(prioik::FLAG_STALLED);
    m.attr("ACTIVE_SET_CODES") = codes;
    NumpyHandles::get();    // under the import's GIL, before any call can race for it
    bind_certificate(m);
    nb::class_<ActiveSetSolver>(m, "ActiveSetSolver",
                                "The hierarchical active set prepared for one layout "
                                "(core/include/prioik/active_set.hpp); one thread at a time.")
        .def(
            "__init__",
            [](ActiveSetSolver* self, I64 n, IndexIn starts, Int8In row_eq, double rcond,
               double primal_tol, double dual_tol, I64 max_iter, bool warm_start) {
                prioik::ActiveSetLayout layout;
                layout.n = n;
                layout.k = static_cast<I64>(starts.shape(0)) - 1;
                layout.M = static_cast<I64>(row_eq.shape(0));
                layout.starts.assign(starts.data(), starts.data() + starts.shape(0));
                layout.row_eq.assign(row_eq.data(), row_eq.data() + row_eq.shape(0));
                prioik::ActiveSetOptions options{rcond, primal_tol, dual_tol, max_iter,
                                                 warm_start};
                try {
                    new (self) ActiveSetSolver(std::move(layout), options);
                } catch (const std::invalid_argument& e) {
                    raise_input_error(e.what());
                }
            },
            nb::arg("n"), nb::arg("starts"), nb::arg("row_eq"), nb::arg("rcond"),
            nb::arg("primal_tol"), nb::arg("dual_tol"), nb::arg("max_iter"),
            nb::arg("warm_start"))
        .def(
            "solve",
            [](ActiveSetSolver& s, nb::handle A, nb::handle b, nb::handle lower, nb::handle upper,
               nb::handle sw) {
                Inputs in(s.layout(), A, b, lower, upper, sw);
                prioik::SolveCode code;
                {
                    nb::gil_scoped_release release;
                    code = s.solve(in.A, in.b, in.lower, in.upper, in.sw);
                }
                if (code == prioik::SolveCode::not_solved) name_refused_value(s.layout(), in);
                return static_cast<int>(code);
            },
            nb::arg("A"), nb::arg("b"), nb::arg("lower"), nb::arg("upper"),
            nb::arg("sqrt_weight"),
            "The level-by-level active set; the code (1 clean, 2 infeasible levels, 3 read "
            "the summary, 0 not solved: an interval not valid or a level of extreme scale; "
            "a value it cannot read raises CoreInputError naming it).")
        .def(
            "equality_first",
            [](ActiveSetSolver& s, nb::handle A, nb::handle b, nb::handle lower, nb::handle upper,
               nb::handle sw) {
                Inputs in(s.layout(), A, b, lower, upper, sw);
                nb::gil_scoped_release release;
                return static_cast<int>(
                    s.equality_first(in.A, in.b, in.lower, in.upper, in.sw));
            },
            nb::arg("A"), nb::arg("b"), nb::arg("lower"), nb::arg("upper"),
            nb::arg("sqrt_weight"),
            "The warm start's equality-first try; -1 when it is not the answer (a value it "
            "cannot read included: solve() names it).")
        .def("reset", &ActiveSetSolver::reset, "Forget the kept working sets.")
        .def("snapshot", &copy_snapshot, nb::arg("out"),
             "Copy the last solve's values into out (float64, snapshot_size): x (n), "
             "res, w2, ranks, over (k each), iterations (k + 1); integers as doubles.")
        .def_prop_ro("snapshot_size", &snapshot_size, "n + 5 k + 1")
        .def_prop_ro("x", result_view(&prioik::ActiveSetResult::x), "n")
        .def_prop_ro("w2", result_view(&prioik::ActiveSetResult::w2),
                     "k: each level's weighted squared violation")
        .def_prop_ro("res", result_view(&prioik::ActiveSetResult::res), "k: their roots")
        .def_prop_ro("margins", result_view(&prioik::ActiveSetResult::margins),
                     "k + 1: the rank decisions' margins (the tie-break last)")
        .def_prop_ro("iterations", result_view(&prioik::ActiveSetResult::iterations), "k + 1")
        .def_prop_ro("flags", result_view(&prioik::ActiveSetResult::flags),
                     "k + 1: ACTIVE_SET_CODES' FLAG_*")
        .def_prop_ro("ranks", result_view(&prioik::ActiveSetResult::ranks),
                     "k + 1: the rows each level fixed")
        .def_prop_ro("over", result_view(&prioik::ActiveSetResult::over),
                     "k + 1: 1 where a level's violation exceeds primal_tol max(1, ‖x‖)")
        .def_prop_ro("warm_valid", [](nb::handle h) {
            return view(nb::cast<ActiveSetSolver&>(h).workspace().warm_valid, h);
        })
        .def_prop_ro("warm_state", [](nb::handle h) {
            auto& s = nb::cast<ActiveSetSolver&>(h);
            auto& v = s.workspace().warm_state;
            size_t shape[2] = {static_cast<size_t>(s.layout().k + 1),
                               static_cast<size_t>(s.layout().M + s.layout().n)};
            return nb::ndarray<nb::numpy, std::int8_t>(v.data(), 2, shape, h);
        })
        .def_prop_ro("x_norm", [](const ActiveSetSolver& s) { return s.result().x_norm; })
        .def_prop_ro("cap_or_nonfinite",
                     [](const ActiveSetSolver& s) { return s.result().cap_or_nonfinite; },
                     "1: an iteration cap was hit; -1: x or a violation is not finite")
        .def_prop_ro("large", [](const ActiveSetSolver& s) { return s.result().large; })
        .def_prop_ro("ambiguous", [](const ActiveSetSolver& s) { return s.result().ambiguous; })
        .def_prop_ro("unresolved", [](const ActiveSetSolver& s) { return s.result().unresolved; })
        .def_prop_ro("equality_first_state",
                     [](const ActiveSetSolver& s) { return s.result().equality_first; },
                     "1: the answer is the equality-first try's; -1/-2: that try was refuted "
                     "(no row / rows held); 0: not tried")
        .def_prop_ro("next_try", [](const ActiveSetSolver& s) { return s.result().next_try; },
                     "0: the next warm solve runs the active set; 1: it tries the equality rows "
                     "first; 2: with the rows this answer held");
}
