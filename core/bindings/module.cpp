// prioik._core: the Python bindings of the compiled core (nanobind).
//
// Every entry point checks its arrays before C++ reads them: a float64 numpy-compatible
// array on the CPU, C-contiguous, of the layout's shape and not empty; anything else
// raises prioik.formulations.base.CoreInputError naming the array (never a copy, never a
// crash). Non-finite entries and √w ≤ 0 are found by the solve's own pass and raise the
// same error naming the entry. A solve releases the GIL.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <initializer_list>
#include <string>
#include <type_traits>
#include <vector>

#include "prioik/build_info.hpp"
#include "prioik/extended_jacobian.hpp"
#include "array_checks.hpp"
#include "rows_bindings.hpp"

namespace nb = nanobind;
using prioik::Index;

void bind_active_set(nb::module_& m);
void bind_closed_form(nb::module_& m);
void bind_control_step(nb::module_& m);

namespace {

using prioik::bindings::copy1;
using prioik::bindings::copy_out;
using prioik::bindings::numpy_copy1;
using prioik::bindings::input;
using prioik::bindings::optional_output;
using prioik::bindings::stack_input;

template <class T>
nb::ndarray<nb::numpy, const T, nb::ndim<1>> view1(const std::vector<T>& v, nb::handle owner) {
  return nb::ndarray<nb::numpy, const T, nb::ndim<1>>(v.data(), {v.size()}, owner);
}

template <class T>
nb::ndarray<nb::numpy, const T, nb::ndim<2>> view2(const std::vector<T>& v, Index rows,
                                                   Index cols, nb::handle owner) {
  return nb::ndarray<nb::numpy, const T, nb::ndim<2>>(
      v.data(), {static_cast<size_t>(rows), static_cast<size_t>(cols)}, owner);
}

// the Python class of prioik's errors, looked up when one is raised (prioik.formulations
// imports this module)
void raise_prioik(const char* cls, const char* message) {
  nb::object base = nb::module_::import_("prioik.formulations.base");
  PyErr_SetString(base.attr(cls).ptr(), message);
}

using prioik::ExtendedJacobian;
using prioik::ExtendedJacobianBatch;
using prioik::ExtendedJacobianResult;

const ExtendedJacobianResult& solve_one(ExtendedJacobian& self, nb::handle A, nb::handle b,
                                        nb::handle w, nb::handle x, nb::handle residuals,
                                        nb::handle ranks) {
  const Index k = self.levels();
  const prioik::StackArrays data = stack_input(A, b, w, self.rows(), self.cols());
  // the answer's outputs, when given: written after the solve
  double* x_out = optional_output<double>(x, "x", self.cols());
  double* residuals_out = optional_output<double>(residuals, "residuals", k);
  Index* ranks_out = optional_output<Index>(ranks, "ranks", k);
  nb::gil_scoped_release release;
  const ExtendedJacobianResult& res = self.solve(data);
  copy_out(res.x, x_out);
  copy_out(res.residuals, residuals_out);
  copy_out(res.ranks, ranks_out);
  return res;
}

ExtendedJacobianBatch solve_many(ExtendedJacobian& self, nb::handle A, nb::handle b,
                                 nb::handle w, unsigned threads) {
  const Index M = self.rows(), n = self.cols();
  Index shape[3] = {0, 0, 0};
  const double* a = input(A, "A", {-1, M, n}, shape);
  const Index N = shape[0];
  const double* bb = input(b, "b", {N, M});
  const double* ww = input(w, "sqrt_weight", {N, M});
  nb::gil_scoped_release release;
  return self.solve_batch(a, bb, ww, N, threads);
}

}  // namespace

NB_MODULE(_core, m) {
  prioik::bindings::NumpyHandles::get();   // under the import's GIL, before any call needs it
  m.doc() = "prioik's compiled core (C++17): the extended Jacobian's nested pivoted QR, the "
            "hierarchical active set and the closed-form formulations beside them.";

  nb::register_exception_translator([](const std::exception_ptr& p, void*) {
    try {
      std::rethrow_exception(p);
    } catch (const prioik::InputError& e) {
      raise_prioik("CoreInputError", e.what());
    } catch (const prioik::ConcurrentUse& e) {
      raise_prioik("ConcurrentUseError", e.what());
    }
  });

  nb::class_<prioik::BuildInfo>(m, "BuildInfo",
                                "What the core was compiled with (core/CMakeLists.txt).")
      .def_ro("compiler", &prioik::BuildInfo::compiler)
      .def_ro("eigen", &prioik::BuildInfo::eigen)
      .def_ro("native", &prioik::BuildInfo::native, "tuned for the building machine")
      .def_ro("sanitized", &prioik::BuildInfo::sanitized)
      .def_ro("fast_math", &prioik::BuildInfo::fast_math)
      .def_ro("fp_contract", &prioik::BuildInfo::fp_contract,
              "a * b + c contracted into a fused multiply-add")
      .def_ro("vector_clones", &prioik::BuildInfo::vector_clones,
              "the hot functions' clone this CPU runs: 'avx2' or 'default' (a portable "
              "x86-64 GCC build on Linux; the same answers, bit for bit), else 'none'");
  m.def("build_info", &prioik::build_info, "The flags the core was compiled with.");
  bind_active_set(m);
  bind_closed_form(m);
  bind_control_step(m);

  m.attr("AMBIGUITY") = prioik::kAmbiguity;
  m.attr("NEAR_AMBIGUITY") = prioik::kNearAmbiguity;
  m.attr("PRECISION_LIMIT_NORM") = prioik::kPrecisionLimitNorm;
  m.attr("SCALE_HIGH") = prioik::kScaleHigh;
  m.attr("SCALE_LOW") = prioik::kScaleLow;
  m.attr("UNIT_ROWS_GAP") = prioik::kUnitRowsGap;

  nb::class_<ExtendedJacobianResult>(
      m, "ExtendedJacobianResult",
      "One solve's answer, the solver's own (the next solve overwrites it): each read "
      "of an array field returns a new array, which the caller keeps.")
      .def_prop_ro("x", [](nb::handle s) { return numpy_copy1(nb::cast<ExtendedJacobianResult&>(s).x); }, nb::rv_policy::automatic)
      .def_prop_ro("residuals",
                   [](nb::handle s) { return numpy_copy1(nb::cast<ExtendedJacobianResult&>(s).residuals); }, nb::rv_policy::automatic)
      .def_prop_ro("level_mu2",
                   [](nb::handle s) { return numpy_copy1(nb::cast<ExtendedJacobianResult&>(s).level_mu2); }, nb::rv_policy::automatic)
      .def_prop_ro("margins",
                   [](nb::handle s) { return numpy_copy1(nb::cast<ExtendedJacobianResult&>(s).margins); }, nb::rv_policy::automatic)
      .def_prop_ro("ranks",
                   [](nb::handle s) { return numpy_copy1(nb::cast<ExtendedJacobianResult&>(s).ranks); }, nb::rv_policy::automatic)
      .def_ro("flops", &ExtendedJacobianResult::flops,
              "floating-point operations of the nested QR, by formula over its sizes")
      .def_ro("solved", &ExtendedJacobianResult::solved,
              "False: a level's scale is outside [SCALE_LOW, SCALE_HIGH], nothing solved")
      .def_ro("finite", &ExtendedJacobianResult::finite)
      .def_prop_ro("clear", [](const ExtendedJacobianResult& r) {
        return r.solved && r.finite && !r.ambiguous && !r.near_ambiguous && !r.precision_limited;
      }, "solved, finite, every rank decision clear of the (near-)ambiguity band and |x| "
         "below PRECISION_LIMIT_NORM: the answer needs no further check")
      .def_ro("ambiguous", &ExtendedJacobianResult::ambiguous)
      .def_ro("near_ambiguous", &ExtendedJacobianResult::near_ambiguous)
      .def_ro("precision_limited", &ExtendedJacobianResult::precision_limited);

  nb::class_<ExtendedJacobianBatch>(m, "ExtendedJacobianBatch",
                                    "Many stacks' answers, stack s in row s of each array.")
      .def_prop_ro("x", [](nb::handle s) {
        auto& r = nb::cast<ExtendedJacobianBatch&>(s);
        return view2(r.x, r.N, r.n, s);
      })
      .def_prop_ro("residuals", [](nb::handle s) {
        auto& r = nb::cast<ExtendedJacobianBatch&>(s);
        return view2(r.residuals, r.N, r.k, s);
      })
      .def_prop_ro("level_mu2", [](nb::handle s) {
        auto& r = nb::cast<ExtendedJacobianBatch&>(s);
        return view2(r.level_mu2, r.N, r.k, s);
      })
      .def_prop_ro("margins", [](nb::handle s) {
        auto& r = nb::cast<ExtendedJacobianBatch&>(s);
        return view2(r.margins, r.N, r.k, s);
      })
      .def_prop_ro("ranks", [](nb::handle s) {
        auto& r = nb::cast<ExtendedJacobianBatch&>(s);
        return view2(r.ranks, r.N, r.k, s);
      })
      .def_prop_ro("solved", [](nb::handle s) { return view1(nb::cast<ExtendedJacobianBatch&>(s).solved, s); })
      .def_prop_ro("finite", [](nb::handle s) { return view1(nb::cast<ExtendedJacobianBatch&>(s).finite, s); })
      .def_prop_ro("ambiguous",
                   [](nb::handle s) { return view1(nb::cast<ExtendedJacobianBatch&>(s).ambiguous, s); })
      .def_prop_ro("near_ambiguous", [](nb::handle s) {
        return view1(nb::cast<ExtendedJacobianBatch&>(s).near_ambiguous, s);
      });

  nb::class_<ExtendedJacobian>(
      m, "ExtendedJacobian",
      "The extended Jacobian's nested pivoted QR prepared for one layout (eq. 15-18, "
      "selective damping, per-level step bounds): workspaces allocated here, none per "
      "solve. One thread at a time (another's call during a solve raises "
      "ConcurrentUseError).")
      .def("__init__",
           [](ExtendedJacobian* self, std::vector<Index> starts, Index n, double rcond,
              double level_damping, double singular_threshold, std::vector<double> step_bound) {
             prioik::ExtendedJacobianOptions o;
             o.rcond = rcond;
             o.level_damping = level_damping;
             o.singular_threshold = singular_threshold;
             o.step_bound = std::move(step_bound);
             new (self) ExtendedJacobian(std::move(starts), n, std::move(o));
           },
           nb::arg("starts"), nb::arg("n"), nb::kw_only(), nb::arg("rcond"),
           nb::arg("level_damping") = 0.0, nb::arg("singular_threshold") = 0.0,
           nb::arg("step_bound") = std::vector<double>())
      .def("solve", &solve_one, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::arg("x") = nb::none(),
           nb::arg("residuals") = nb::none(), nb::arg("ranks") = nb::none(),
           nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M; C-contiguous float64). x (n), "
           "residuals (k) and ranks (k, int64), when given, receive the answer's.")
      .def("solve_batch", &solve_many, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::kw_only(), nb::arg("threads") = 0,
           "Solve N stacks (A: N × M × n, b and sqrt_weight: N × M), each on its own, on "
           "up to `threads` threads (0: one per hardware thread).")
      .def_prop_ro("rows", &ExtendedJacobian::rows)
      .def_prop_ro("cols", &ExtendedJacobian::cols)
      .def_prop_ro("levels", &ExtendedJacobian::levels)
      .def_prop_ro("trust_region", &ExtendedJacobian::trust_region);

  register_rows(m);
}
