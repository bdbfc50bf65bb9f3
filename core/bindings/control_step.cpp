// prioik._core.ControlStep: the prepared control step's bindings (control_step.hpp).
//
// Built once by prioik.robots.ControlStep: every array given at prepare is checked
// (float64 or int64, its shape; any strides where the step reads a view of pinocchio's
// Data, C-contiguous for the stack's arrays) and held for the step's life, so the views
// the step reads stay valid. A step takes q (a C-contiguous float64 array of n_q
// entries, else CoreInputError naming q) and releases the GIL; a second thread in a step
// raises ConcurrentUseError. The tasks' references are numpy views of the step's own
// buffers, written by Python.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "array_checks.hpp"
#include "prioik/active_set.hpp"
#include "prioik/control_step.hpp"
#include "prioik/extended_jacobian.hpp"

namespace nb = nanobind;

namespace {

using prioik::InputError;
using prioik::rows::ConstMatrix;
using prioik::rows::ConstVector;
using prioik::rows::Index;
using prioik::rows::Matrix;
using prioik::rows::Vector;

using AnyFloat = nb::ndarray<double, nb::device::cpu>;
using AnyFloatRO = nb::ndarray<nb::ro, double, nb::device::cpu>;
using AnyIndex = nb::ndarray<nb::ro, std::int64_t, nb::device::cpu>;

using prioik::bindings::kNumpyAligned;
using prioik::bindings::kNumpyWriteable;
using prioik::bindings::NumpyArrayFields;
using prioik::bindings::NumpyHandles;

// an exact numpy.ndarray of float64 (native byte order), aligned, read from its fields;
// else nullptr
const NumpyArrayFields* float64_fields(nb::handle h) {
    const NumpyHandles& numpy = NumpyHandles::get();
    if (numpy.ndarray == nullptr || Py_TYPE(h.ptr()) != numpy.ndarray) return nullptr;
    const auto* a = reinterpret_cast<const NumpyArrayFields*>(h.ptr());
    return a->descr == numpy.float64 && (a->flags & kNumpyAligned) ? a : nullptr;
}

std::string shape_text(const std::vector<Index>& got) {
    std::string out = "(";
    for (size_t i = 0; i < got.size(); ++i) out += (i ? ", " : "") + std::to_string(got[i]);
    return out + (got.size() == 1 ? ",)" : ")");
}

// an array argument `name` of dtype T, ndim dims, its shape checked (-1: any)
template <class Array>
Array take(nb::handle h, const char* name, std::vector<Index> want) {
    Array a;
    if (h.is_none() || !nb::try_cast(h, a, false))
        throw InputError(std::string(name) + " must be a " +
                         (std::is_same_v<typename Array::Scalar, std::int64_t> ? "int64"
                                                                               : "float64") +
                         " numpy array" + (Array::ReadOnly ? "" : " (writable)"));
    std::vector<Index> got(a.ndim());
    for (size_t d = 0; d < a.ndim(); ++d) got[d] = static_cast<Index>(a.shape(d));
    bool ok = got.size() == want.size();
    for (size_t d = 0; ok && d < want.size(); ++d) ok = want[d] < 0 || got[d] == want[d];
    if (!ok) {
        std::vector<Index> w(want);
        throw InputError(std::string(name) + " must have shape " + shape_text(w) +
                         " (-1: any), got " + shape_text(got));
    }
    return a;
}

ConstMatrix cmatrix(const AnyFloatRO& a) {
    return ConstMatrix{a.data(), static_cast<Index>(a.shape(0)), static_cast<Index>(a.shape(1)),
                       static_cast<Index>(a.stride(0)), static_cast<Index>(a.stride(1))};
}

ConstVector cvector(const AnyFloatRO& a) {
    return ConstVector{a.data(), static_cast<Index>(a.shape(0)), static_cast<Index>(a.stride(0))};
}

template <class T, class Array>
std::vector<T> copied(const Array& a) {
    std::vector<T> out;
    if (a.ndim() == 1) {
        for (size_t i = 0; i < a.shape(0); ++i) out.push_back(a.data()[i * a.stride(0)]);
    } else {
        for (size_t i = 0; i < a.shape(0); ++i)
            for (size_t j = 0; j < a.shape(1); ++j)
                out.push_back(a.data()[i * a.stride(0) + j * a.stride(1)]);
    }
    return out;
}

// the stack's arrays: C-contiguous
void contiguous(const AnyFloat& a, const char* name) {
    Index expect = 1;
    for (Index d = static_cast<Index>(a.ndim()) - 1; d >= 0; --d) {
        if (a.shape(d) > 1 && a.stride(d) != expect)
            throw InputError(std::string(name) + " must be C-contiguous");
        expect *= static_cast<Index>(a.shape(d));
    }
}

// The bound object: the step and every array its views read (held for its life).
struct PyControlStep {
    std::unique_ptr<prioik::ControlStep> step;
    std::vector<nb::object> held;
    Index nq = 0, nv = 0;

    void hold(nb::handle h) { held.push_back(nb::borrow(h)); }
};

// a frame op from its views (the parent joint's placement) and constants
prioik::FrameOp frame_op(PyControlStep& s, nb::handle joint_t, nb::handle joint_R,
                         nb::handle local_t, nb::handle local_R, nb::handle spec,
                         nb::handle geo, bool position_only) {
    prioik::FrameOp op;
    const AnyFloatRO jt = take<AnyFloatRO>(joint_t, "joint_t", {3});
    const AnyFloatRO jR = take<AnyFloatRO>(joint_R, "joint_R", {3, 3});
    s.hold(joint_t);
    s.hold(joint_R);
    op.placement.joint_t = cvector(jt);
    op.placement.joint_R = cmatrix(jR);
    const std::vector<double> lt = copied<double>(take<AnyFloatRO>(local_t, "local_t", {3}));
    const std::vector<double> lR = copied<double>(take<AnyFloatRO>(local_R, "local_R", {3, 3}));
    std::copy(lt.begin(), lt.end(), op.placement.local_t.begin());
    std::copy(lR.begin(), lR.end(), op.placement.local_R.begin());
    op.spec = copied<std::int64_t>(take<AnyIndex>(spec, "spec", {-1}));
    const std::vector<double> g = copied<double>(take<AnyFloatRO>(geo, "geo", {5, 3}));
    std::copy(g.begin(), g.end(), op.geo.begin());
    op.position_only = position_only;
    if (op.spec.size() < 3) throw InputError("spec must hold at least 3 entries");
    if (op.spec[1] < 0 || op.spec[1] > 2 || (position_only && op.spec[1] != 0))
        throw InputError("spec[1] is not a row set (0: position, 1: orientation, 2: pose)");
    for (size_t k = 3; k < op.spec.size(); ++k)
        if (op.spec[k] < 0 || op.spec[k] >= s.nv)
            throw InputError("spec[" + std::to_string(k) + "] is not a column");
    return op;
}

template <class T>
nb::ndarray<nb::numpy, T> view(std::vector<T>& v, nb::handle owner) {
    size_t shape[1] = {v.size()};
    return nb::ndarray<nb::numpy, T>(v.data(), 1, shape, owner);
}

prioik::ControlStep& step_of(PyControlStep& s) {
    if (!s.step) throw InputError("the control step is not built");
    return *s.step;
}

// q as the step reads it: a C-contiguous float64 numpy array of n_q entries
const double* q_of(nb::handle q, Index nq) {
    const NumpyArrayFields* a = float64_fields(q);
    if (a != nullptr && a->nd == 1 && a->dimensions[0] == nq && (nq <= 1 || a->strides[0] == 8))
        return reinterpret_cast<const double*>(a->data);
    throw InputError("q must be a C-contiguous float64 numpy array of " + std::to_string(nq) +
                     " entries");
}

void build(PyControlStep* self, nb::handle solver, nb::handle A, nb::handle b,
           nb::handle lower, nb::handle upper, nb::handle sw, nb::handle Q, nb::handle J,
           Index nq, double dt, nb::handle unit, nb::handle joints, bool integrable) {
    // built in a local object, placed in self once complete (an error on the way
    // releases what it holds: nanobind runs no destructor for a failed __init__)
    PyControlStep built;
    prioik::ActiveSetSolver* as = nullptr;
    if (!nb::try_cast<prioik::ActiveSetSolver*>(solver, as) || as == nullptr)
        throw InputError("solver must be a prioik._core.ActiveSetSolver");
    built.hold(solver);
    const Index M = as->layout().M, n = as->layout().n;
    built.nq = nq;
    built.nv = n;
    AnyFloat a = take<AnyFloat>(A, "A", {M, n});
    AnyFloat bb = take<AnyFloat>(b, "b", {M});
    AnyFloat lo = take<AnyFloat>(lower, "lower", {M});
    AnyFloat up = take<AnyFloat>(upper, "upper", {M});
    AnyFloat w = take<AnyFloat>(sw, "sqrt_weight", {M});
    AnyFloat q = take<AnyFloat>(Q, "Q", {6, M});
    const AnyFloatRO j = take<AnyFloatRO>(J, "J", {6, n});
    for (auto [arr, name] : {std::pair{&a, "A"}, {&bb, "b"}, {&lo, "lower"}, {&up, "upper"},
                             {&w, "sqrt_weight"}, {&q, "Q"}})
        contiguous(*arr, name);
    for (nb::handle h : {A, b, lower, upper, sw, Q, J}) built.hold(h);
    prioik::ControlStepArrays arrays;
    arrays.A = Matrix{a.data(), M, n, n, 1};
    arrays.b = Vector{bb.data(), M, 1};
    arrays.lower = Vector{lo.data(), M, 1};
    arrays.upper = Vector{up.data(), M, 1};
    arrays.sqrt_weight = w.data();
    arrays.Q = Matrix{q.data(), 6, M, M, 1};
    arrays.J = cmatrix(j);
    std::vector<std::int64_t> u = copied<std::int64_t>(take<AnyIndex>(unit, "unit", {-1}));
    for (size_t p = 0; p + 1 < u.size(); p += 2)
        if (u[p] < 0 || u[p + 1] < 0 || u[p] + u[p + 1] > nq)
            throw InputError("unit's part " + std::to_string(p / 2) + " is not within q");
    const AnyIndex js = take<AnyIndex>(joints, "joints", {-1, 5});
    std::vector<prioik::JointSegment> segments;
    for (size_t i = 0; i < js.shape(0); ++i) {
        auto at = [&](size_t c) { return js.data()[i * js.stride(0) + c * js.stride(1)]; };
        prioik::JointSegment s{at(0), at(1), at(2), at(3), at(4) != 0};
        const bool fits = s.idx_q >= 0 && s.idx_v >= 0 && s.idx_q + s.nq <= nq &&
                          s.idx_v + s.nv <= n && (s.free_flyer ? s.nq == 7 && s.nv == 6
                                                               : s.nq == s.nv);
        if (!fits) throw InputError("joints' row " + std::to_string(i) + " is not a joint of q");
        segments.push_back(s);
    }
    built.step = std::make_unique<prioik::ControlStep>(*as, arrays, nq, dt, std::move(u),
                                                       std::move(segments), integrable);
    new (self) PyControlStep(std::move(built));
}

// buffer[offset : offset + size] = value, a float64 numpy array of shape (rows,) (cols
// < 0) or (rows, cols), any strides, read in C order: the index of value's first entry
// that is not finite (nothing written), or -1. Anything else raises InputError.
Index put_reference(nb::handle buffer, Index offset, nb::handle value, Index rows, Index cols) {
    const Index ncols = cols < 0 ? 1 : cols;
    const NumpyArrayFields* out = float64_fields(buffer);
    if (out == nullptr || out->nd != 1 || (out->dimensions[0] > 1 && out->strides[0] != 8) ||
        !(out->flags & kNumpyWriteable) || rows < 0 || offset < 0 ||
        offset + rows * ncols > out->dimensions[0])
        throw InputError("buffer must be a writable float64 vector holding the reference");
    const NumpyArrayFields* in = float64_fields(value);
    if (in == nullptr) throw InputError("the reference must be a float64 numpy array");
    const bool fits = cols < 0 ? in->nd == 1 && in->dimensions[0] == rows
                               : in->nd == 2 && in->dimensions[0] == rows &&
                                     in->dimensions[1] == cols;
    if (!fits) throw InputError("the reference is not of its shape");
    const Py_ssize_t rs = in->strides[0], cs = cols < 0 ? 0 : in->strides[1];
    auto at = [&](Index i, Index j) {
        return *reinterpret_cast<const double*>(in->data + i * rs + j * cs);
    };
    for (Index i = 0; i < rows; ++i)
        for (Index j = 0; j < ncols; ++j)
            if (!std::isfinite(at(i, j))) return i * ncols + j;
    double* dst = reinterpret_cast<double*>(out->data) + offset;
    for (Index i = 0; i < rows; ++i)
        for (Index j = 0; j < ncols; ++j) dst[i * ncols + j] = at(i, j);
    return -1;
}

}  // namespace

void bind_control_step(nb::module_& m) {
    NumpyHandles::get();    // under the import's GIL, before any call can race for it
    auto a = [](const char* name) { return nb::arg(name).none(); };
    m.def("put_reference", &put_reference, a("buffer"), nb::arg("offset"), a("value"),
          nb::arg("rows"), nb::arg("cols"),
          "buffer[offset:] = value (float64 of shape (rows,) when cols < 0, else (rows, "
          "cols); read in C order): the index of its first entry that is not finite "
          "(nothing written), or -1.");
    nb::class_<PyControlStep>(m, "ControlStep",
                              "A prepared velocity-level control step "
                              "(core/include/prioik/control_step.hpp): prioik.robots."
                              "ControlStep builds it; one thread at a time.")
        .def("__init__", &build, a("solver"), a("A"), a("b"), a("lower"), a("upper"),
             a("sqrt_weight"), a("Q"), a("J"), nb::arg("nq"), nb::arg("dt"), a("unit"),
             a("joints"), nb::arg("integrable"))
        .def(
            "set_com",
            [](PyControlStep& s, nb::handle Jcom, nb::handle com) {
                const AnyFloatRO jc = take<AnyFloatRO>(Jcom, "Jcom", {3, s.nv});
                const AnyFloatRO c = take<AnyFloatRO>(com, "com", {3});
                s.hold(Jcom);
                s.hold(com);
                auto& step = step_of(s);
                step.set_com(cmatrix(jc), cvector(c));
            },
            a("Jcom"), a("com"), "Views of data.Jcom and data.com[0] (CoM tasks).")
        .def(
            "add_frame",
            [](PyControlStep& s, nb::handle joint_t, nb::handle joint_R, nb::handle local_t,
               nb::handle local_R, nb::handle spec, nb::handle geo, bool position_only) {
                auto& step = step_of(s);
                prioik::FrameOp op = frame_op(s, joint_t, joint_R, local_t, local_R, spec,
                                              geo, position_only);
                const Index rows = position_only ? 3 : (op.spec[1] == 2 ? 6 : 3);
                if (op.spec[0] < 0 || op.spec[0] + rows > step.rows())
                    throw InputError("spec's rows are outside the stack");
                op.A = step.stack_rows();
                op.Q = step.per_row();
                return step.add_frame(std::move(op));
            },
            a("joint_t"), a("joint_R"), a("local_t"), a("local_R"), a("spec"), a("geo"),
            nb::arg("position_only"),
            "A frame task's rows (rows.hpp's frame writers); returns its index.")
        .def(
            "add_com",
            [](PyControlStep& s, Index start, nb::handle axes) {
                auto& step = step_of(s);
                prioik::ComOp op;
                op.start = start;
                op.axes = copied<std::int64_t>(take<AnyIndex>(axes, "axes", {-1}));
                for (std::int64_t ax : op.axes)
                    if (ax < 0 || ax > 2) throw InputError("axes must be among 0, 1, 2");
                if (start < 0 || start + static_cast<Index>(op.axes.size()) > step.rows())
                    throw InputError("the CoM task's rows are outside the stack");
                if (!step.has_com()) throw InputError("set_com first");
                op.ref.assign(2 * op.axes.size(), 0.0);
                return step.add_com(std::move(op));
            },
            nb::arg("start"), a("axes"), "A CoM task; returns its index.")
        .def(
            "add_posture",
            [](PyControlStep& s, Index start, nb::handle iq) {
                auto& step = step_of(s);
                prioik::PostureOp op;
                op.start = start;
                op.iq = copied<std::int64_t>(take<AnyIndex>(iq, "iq", {-1}));
                for (std::int64_t i : op.iq)
                    if (i < 0 || i >= s.nq) throw InputError("iq's entries must index q");
                if (start < 0 || start + static_cast<Index>(op.iq.size()) > step.rows())
                    throw InputError("the posture's rows are outside the stack");
                op.ref.assign(static_cast<size_t>(s.nq), 0.0);
                return step.add_posture(std::move(op));
            },
            nb::arg("start"), a("iq"), "A posture task; returns its index.")
        .def(
            "add_limits",
            [](PyControlStep& s, bool bounds, nb::handle iq, nb::handle lim, nb::handle params) {
                auto& step = step_of(s);
                prioik::LimitOp op;
                op.bounds = bounds;
                op.iq = copied<std::int64_t>(take<AnyIndex>(iq, "iq", {-1}));
                const Index na = static_cast<Index>(op.iq.size());
                for (std::int64_t i : op.iq)
                    if (i < 0 || i >= s.nq) throw InputError("iq's entries must index q");
                op.lim = copied<double>(take<AnyFloatRO>(lim, "lim", {3, na}));
                op.params = copied<double>(take<AnyFloatRO>(params, "params", {bounds ? 6 : 4}));
                const double start = op.params[0];
                const Index first = static_cast<Index>(start);
                if (!(start >= 0.0 && static_cast<double>(first) == start) ||
                    first + na > step.rows() || na > s.nv)
                    throw InputError("the joint limits' rows are outside the stack");
                if (!bounds && (op.params[1] < 0.0 || op.params[1] + na > s.nv))
                    throw InputError("params[1] (n_base) leaves the joints' columns outside A");
                return step.add_limits(std::move(op));
            },
            nb::arg("bounds"), a("iq"), a("lim"), a("params"),
            "Joint limits (bounds_at or activation_at); returns the index.")
        .def(
            "add_region",
            [](PyControlStep& s, Index start, nb::handle C, double T, double dt,
               nb::handle joint_t, nb::handle joint_R, nb::handle local_t, nb::handle local_R,
               nb::handle spec, nb::handle geo) {
                auto& step = step_of(s);
                prioik::RegionOp op;
                op.start = start;
                op.C = copied<double>(take<AnyFloatRO>(C, "C", {-1, 3}));
                const Index k = static_cast<Index>(op.C.size() / 3);
                op.lo.assign(k, 0.0);
                op.hi.assign(k, 0.0);
                op.T = T;
                op.dt = dt;
                if (start < 0 || start + k > step.rows())
                    throw InputError("the region's rows are outside the stack");
                op.on_frame = !joint_t.is_none();
                if (op.on_frame) {
                    op.point = frame_op(s, joint_t, joint_R, local_t, local_R, spec, geo, true);
                    if (op.point.spec[0] != 0)
                        throw InputError("a region's point rows start at 0 (spec[0])");
                }
                else if (!step.has_com())
                    throw InputError("set_com first");
                return step.add_region(std::move(op));
            },
            nb::arg("start"), a("C"), nb::arg("T"), nb::arg("dt"), a("joint_t"), a("joint_R"),
            a("local_t"), a("local_R"), a("spec"), a("geo"),
            "A frame (joint_t given) or CoM region; returns its index.")
        .def(
            "add_cap",
            [](PyControlStep& s, Index start, Index stop, double cap) {
                auto& step = step_of(s);
                if (start < 0 || stop < start || stop > step.rows())
                    throw InputError("the capped rows are outside the stack");
                step.add_cap(start, stop, cap);
            },
            nb::arg("start"), nb::arg("stop"), nb::arg("cap"), "A task's max_rate.")
        .def(
            "set_hard",
            [](PyControlStep& s, nb::handle levels, double tol) {
                auto& step = step_of(s);
                try {
                    step.set_hard(copied<std::int64_t>(take<AnyIndex>(levels, "levels", {-1})),
                                  tol);
                } catch (const std::invalid_argument& e) {
                    throw InputError(e.what());
                }
            },
            a("levels"), nb::arg("tol"),
            "The hard levels and the certificate's tolerance (a clean answer is the step's "
            "only when each holds clearly; else step() returns 4).")
        .def(
            "step",
            [](PyControlStep& s, nb::handle q) {
                auto& step = step_of(s);
                const double* qp = q_of(q, s.nq);
                nb::gil_scoped_release release;
                return static_cast<int>(step.step(qp));
            },
            a("q"),
            "One step at q: the code (1 clean, 2 infeasible levels: q_next and velocity "
            "written; 3 read the solver's summary; 0 not solved; 4 clean but a hard level "
            "not clearly held: check it; -3 q not valid). `code` holds the kernel's.")
        .def(
            "integrate",
            [](PyControlStep& s, nb::handle q, nb::handle v, nb::handle out) {
                auto& step = step_of(s);
                if (!step.integrable())
                    throw InputError("the robot has joints the step does not integrate");
                const double* qp = q_of(q, s.nq);
                const AnyFloatRO va = take<AnyFloatRO>(v, "v", {s.nv});
                AnyFloat o = take<AnyFloat>(out, "out", {s.nq});
                contiguous(o, "out");
                if (va.stride(0) != 1 && s.nv > 1) throw InputError("v must be C-contiguous");
                nb::gil_scoped_release release;
                step.integrate(qp, va.data(), o.data());
            },
            a("q"), a("v"), a("out"), "out = q ⊕ v dt (pinocchio's integrate).")
        .def_prop_ro("integrable", [](PyControlStep& s) { return step_of(s).integrable(); })
        .def_prop_ro("q_next",
                     [](nb::handle h) {
                         auto& s = nb::cast<PyControlStep&>(h);
                         return view(step_of(s).result().q_next, h);
                     })
        .def_prop_ro("velocity",
                     [](nb::handle h) {
                         auto& s = nb::cast<PyControlStep&>(h);
                         return view(step_of(s).result().velocity, h);
                     })
        .def_prop_ro("code", [](PyControlStep& s) { return step_of(s).result().code; })
        .def_prop_ro("equality_first",
                     [](PyControlStep& s) { return step_of(s).result().equality_first; })
        .def_prop_ro("solve_time_s",
                     [](PyControlStep& s) { return step_of(s).result().solve_time_s; })
        .def(
            "frame_reference",
            [](nb::handle h, Index i) {
                auto& step = step_of(nb::cast<PyControlStep&>(h));
                if (i < 0 || i >= static_cast<Index>(step.frames().size()))
                    throw InputError("no such frame task");
                return view(step.frames()[i].ref, h);
            },
            nb::arg("i"), "The frame task's reference: x, xd, R* (row-major), w (18).")
        .def(
            "com_reference",
            [](nb::handle h, Index i) {
                auto& step = step_of(nb::cast<PyControlStep&>(h));
                if (i < 0 || i >= static_cast<Index>(step.coms().size()))
                    throw InputError("no such CoM task");
                return view(step.coms()[i].ref, h);
            },
            nb::arg("i"), "The CoM task's reference: x, xd (on its axes).")
        .def(
            "posture_reference",
            [](nb::handle h, Index i) {
                auto& step = step_of(nb::cast<PyControlStep&>(h));
                if (i < 0 || i >= static_cast<Index>(step.postures().size()))
                    throw InputError("no such posture task");
                return view(step.postures()[i].ref, h);
            },
            nb::arg("i"), "The posture's q_ref (n_q).")
        .def(
            "region_reference",
            [](nb::handle h, Index i) {
                auto& step = step_of(nb::cast<PyControlStep&>(h));
                if (i < 0 || i >= static_cast<Index>(step.regions().size()))
                    throw InputError("no such region task");
                auto& r = step.regions()[i];
                return nb::make_tuple(view(r.C, h), view(r.lo, h), view(r.hi, h));
            },
            nb::arg("i"), "The region's C (k x 3, flat), lower, upper.");
}
