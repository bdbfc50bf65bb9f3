// prioik._core's closed-form formulations beside the extended Jacobian (closed_form.hpp),
// nullspace, chiaverini, unifying, operational_space, reference and sns:
// prepared solvers whose solve checks its arrays (array_checks.hpp: float64, the layout's
// shape, C-contiguous, not empty) and raises CoreInputError naming the array or the
// entry at fault; a solve releases the GIL.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "array_checks.hpp"
#include "prioik/closed_form.hpp"

namespace nb = nanobind;
using prioik::Index;
using prioik::bindings::copy1;
using prioik::bindings::copy_out;
using prioik::bindings::input;
using prioik::bindings::optional_output;
using prioik::bindings::stack_input;

namespace {

using prioik::ChiaveriniResult;
using prioik::ChiaveriniSolver;
using prioik::NullspaceResult;
using prioik::NullspaceSolver;
using prioik::OperationalSpaceSolver;
using prioik::ProjectionResult;
using prioik::ReferenceResult;
using prioik::ReferenceSolver;
using prioik::SnsResult;
using prioik::SnsSolver;
using prioik::UnifyingResult;
using prioik::UnifyingSolver;

// The stack's arrays checked against the solver's layout (M × n, M, M).
template <class Solver>
prioik::StackArrays stack_arrays(const Solver& self, nb::handle A, nb::handle b, nb::handle w) {
  return stack_input(A, b, w, self.rows(), self.cols());
}

// a solve of the stack alone (chiaverini, reference)
template <class Solver>
const auto& solve_stack(Solver& self, nb::handle A, nb::handle b, nb::handle w) {
  const prioik::StackArrays data = stack_arrays(self, A, b, w);
  nb::gil_scoped_release release;
  return self.solve(data);
}

const NullspaceResult& solve_nullspace(NullspaceSolver& self, nb::handle A, nb::handle b,
                                       nb::handle w, nb::handle x, nb::handle residuals) {
  const prioik::StackArrays data = stack_arrays(self, A, b, w);
  double* x_out = optional_output<double>(x, "x", self.cols());
  double* residuals_out = optional_output<double>(residuals, "residuals", self.levels());
  nb::gil_scoped_release release;
  const NullspaceResult& res = self.solve(data);
  copy_out(res.x, x_out);
  copy_out(res.residuals, residuals_out);
  return res;
}

// a solve with a mass matrix (unifying, operational_space), M checked as n × n
template <class Solver>
const UnifyingResult& solve_with_mass(Solver& self, nb::handle A, nb::handle b, nb::handle w,
                                      nb::handle mass_matrix) {
  const prioik::StackArrays data = stack_arrays(self, A, b, w);
  const double* mass = input(mass_matrix, "mass_matrix", {self.cols(), self.cols()});
  nb::gil_scoped_release release;
  return self.solve(data, mass);
}

// ReferenceSolver(starts, n, rcond=, level_damping=, metric=): the metric (n × n) checked
// as the stack's arrays are
void init_reference(ReferenceSolver* self, std::vector<Index> starts, Index n, double rcond,
                    std::vector<double> level_damping, nb::handle metric) {
  prioik::ReferenceOptions o;
  o.rcond = rcond;
  o.level_damping = std::move(level_damping);
  if (!metric.is_none()) {
    if (n <= 0) throw prioik::InputError("n must be positive, got " + std::to_string(n));
    const double* W = input(metric, "metric", {n, n});
    o.metric.assign(W, W + n * n);
  }
  new (self) ReferenceSolver(std::move(starts), n, std::move(o));
}

// an SNS solve: the stack's arrays and the rows' bounds (lower, upper: M) checked
const SnsResult& solve_sns(SnsSolver& self, nb::handle A, nb::handle b, nb::handle w,
                           nb::handle lower, nb::handle upper) {
  const prioik::StackArrays data = stack_arrays(self, A, b, w);
  const double* lo = input(lower, "lower", {self.rows()});
  const double* up = input(upper, "upper", {self.rows()});
  nb::gil_scoped_release release;
  return self.solve(data, lo, up);
}

const char* const kScaleUnsolved =
    "False: a level's scale is outside [SCALE_LOW, SCALE_HIGH], nothing solved";

// The fields every answer holds (ProjectionResult): x, residuals, flops, solved, finite;
// each read of an array field returns a new array
template <class Result>
nb::class_<Result> bind_result(nb::module_& m, const char* name, const char* doc,
                               const char* solved_doc = kScaleUnsolved,
                               const char* residuals_doc = nullptr) {
  nb::class_<Result> cls(m, name, doc);
  cls.def_prop_ro("x", [](const Result& r) { return copy1(r.x); }, nb::rv_policy::move);
  auto residuals = [](const Result& r) { return copy1(r.residuals); };
  if (residuals_doc != nullptr)
    cls.def_prop_ro("residuals", residuals, nb::rv_policy::move, residuals_doc);
  else
    cls.def_prop_ro("residuals", residuals, nb::rv_policy::move);
  cls.def_ro("flops", &ProjectionResult::flops, "floating-point operations of the solve")
      .def_ro("solved", &ProjectionResult::solved, solved_doc)
      .def_ro("finite", &ProjectionResult::finite);
  return cls;
}

// A prepared solver's class: its layout's rows, cols and levels read-only
template <class Solver>
nb::class_<Solver> bind_solver(nb::module_& m, const char* name, const char* doc) {
  nb::class_<Solver> cls(m, name, doc);
  cls.def_prop_ro("rows", [](const Solver& s) { return s.rows(); })
      .def_prop_ro("cols", [](const Solver& s) { return s.cols(); })
      .def_prop_ro("levels", [](const Solver& s) { return s.levels(); });
  return cls;
}

}  // namespace

void bind_closed_form(nb::module_& m) {
  bind_result<NullspaceResult>(
      m, "NullspaceResult",
      "One null-space projection solve's answer, the solver's own (the next solve "
      "overwrites it): each read of an array field returns a new array.")
      .def_prop_ro("min_pivots", [](const NullspaceResult& r) { return copy1(r.min_pivots); },
                   nb::rv_policy::move, "the smallest kept pivot norm of each Ĵ_i (0: none)")
      .def_prop_ro("margins", [](const NullspaceResult& r) { return copy1(r.margins); },
                   nb::rv_policy::move)
      .def_prop_ro("ranks", [](const NullspaceResult& r) { return copy1(r.ranks); },
                   nb::rv_policy::move)
      .def_ro("ambiguous", &NullspaceResult::ambiguous);

  bind_solver<NullspaceSolver>(
      m, "NullspaceSolver",
      "Recursive null-space projection prepared for one layout (closed_form.hpp): "
      "workspaces allocated here, none per solve. One thread at a time.")
      .def("__init__",
           [](NullspaceSolver* self, std::vector<Index> starts, Index n, double rcond,
              double damping, bool reproject) {
             prioik::NullspaceOptions o;
             o.rcond = rcond;
             o.damping = damping;
             o.reproject = reproject;
             new (self) NullspaceSolver(std::move(starts), n, o);
           },
           nb::arg("starts"), nb::arg("n"), nb::kw_only(), nb::arg("rcond"),
           nb::arg("damping") = 0.0, nb::arg("reproject") = true)
      .def("solve", &solve_nullspace, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::arg("x") = nb::none(),
           nb::arg("residuals") = nb::none(), nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M; C-contiguous float64); x (n) "
           "and residuals (k), when given, receive the answer's.");

  bind_result<ChiaveriniResult>(
      m, "ChiaveriniResult",
      "One Chiaverini solve's answer, the solver's own (the next solve overwrites it): "
      "each read of an array field returns a new array.")
      .def_prop_ro("task_solutions",
                   [](const ChiaveriniResult& r) { return copy1(r.task_solutions); },
                   nb::rv_policy::move, "k × n, flattened: row i = A_i^# b_i");

  bind_solver<ChiaveriniSolver>(
      m, "ChiaveriniSolver",
      "Chiaverini's task priority prepared for one layout (closed_form.hpp): workspaces "
      "allocated here, none per solve. One thread at a time.")
      .def("__init__",
           [](ChiaveriniSolver* self, std::vector<Index> starts, Index n, double rcond,
              double damping) {
             prioik::ChiaveriniOptions o;
             o.rcond = rcond;
             o.damping = damping;
             new (self) ChiaveriniSolver(std::move(starts), n, o);
           },
           nb::arg("starts"), nb::arg("n"), nb::kw_only(), nb::arg("rcond"),
           nb::arg("damping") = 0.0)
      .def("solve", &solve_stack<ChiaveriniSolver>, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M; C-contiguous float64).");

  bind_result<UnifyingResult>(
      m, "UnifyingResult",
      "One unifying-framework solve's answer, the solver's own (the next solve overwrites "
      "it): each read of an array field returns a new array.",
      "False: M is not positive definite, or a level's scale is outside "
      "[SCALE_LOW, SCALE_HIGH]; nothing solved")
      .def_prop_ro("ranks", [](const UnifyingResult& r) { return copy1(r.ranks); },
                   nb::rv_policy::move, "the kept rank of each A_i M⁻¹")
      .def_ro("mass_positive_definite", &UnifyingResult::mass_positive_definite);

  bind_solver<UnifyingSolver>(
      m, "UnifyingSolver",
      "The unifying framework (eq. 40) prepared for one layout (closed_form.hpp): "
      "workspaces allocated here, none per solve; M given with each solve. One thread at "
      "a time.")
      .def(nb::init<std::vector<Index>, Index, double>(), nb::arg("starts"), nb::arg("n"),
           nb::kw_only(), nb::arg("rcond"))
      .def("solve", &solve_with_mass<UnifyingSolver>, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::arg("mass_matrix").none(),
           nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M, mass_matrix: n × n SPD; "
           "C-contiguous float64).");

  bind_solver<OperationalSpaceSolver>(
      m, "OperationalSpaceSolver",
      "Prioritized operational-space control prepared for one layout (closed_form.hpp): "
      "workspaces allocated here, none per solve; M given with each solve (its answer a "
      "UnifyingResult). One thread at a time.")
      .def("__init__",
           [](OperationalSpaceSolver* self, std::vector<Index> starts, Index n, double rcond,
              bool reproject) {
             prioik::OperationalSpaceOptions o;
             o.rcond = rcond;
             o.reproject = reproject;
             new (self) OperationalSpaceSolver(std::move(starts), n, o);
           },
           nb::arg("starts"), nb::arg("n"), nb::kw_only(), nb::arg("rcond"),
           nb::arg("reproject") = true)
      .def("solve", &solve_with_mass<OperationalSpaceSolver>, nb::arg("A").none(),
           nb::arg("b").none(), nb::arg("sqrt_weight").none(), nb::arg("mass_matrix").none(),
           nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M, mass_matrix: n × n SPD; "
           "C-contiguous float64).");

  bind_result<ReferenceResult>(
      m, "ReferenceResult",
      "One nested-SVD reference solve's answer, the solver's own (the next solve "
      "overwrites it): each read of an array field returns a new array.")
      .def_prop_ro("ranks", [](const ReferenceResult& r) { return copy1(r.ranks); },
                   nb::rv_policy::move, "the kept rank of each M_i = A_i Z_i")
      .def_prop_ro("ambiguous", [](const ReferenceResult& r) { return copy1(r.ambiguous); },
                   nb::rv_policy::move,
                   "1 where a singular value of M_i lies within AMBIGUITY of the threshold")
      .def_ro("null_space_dim", &ReferenceResult::null_space_dim)
      .def_ro("sweeps", &ReferenceResult::sweeps, "the Jacobi sweeps of the solve")
      .def_ro("rotations", &ReferenceResult::rotations, "the Jacobi rotations of the solve")
      .def_ro("metric_positive_definite", &ReferenceResult::metric_positive_definite,
              "False: ZᵀWZ is not positive definite (x without the metric's tie-break)");

  bind_solver<ReferenceSolver>(
      m, "ReferenceSolver",
      "The nested-SVD lexicographic least squares prepared for one layout "
      "(closed_form.hpp): workspaces allocated here, none per solve. One thread at a time.")
      .def("__init__", &init_reference, nb::arg("starts"), nb::arg("n"), nb::kw_only(),
           nb::arg("rcond"), nb::arg("level_damping") = std::vector<double>(),
           nb::arg("metric") = nb::none())
      .def("solve", &solve_stack<ReferenceSolver>, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b and sqrt_weight: M; C-contiguous float64).");

  bind_result<SnsResult>(
      m, "SnsResult",
      "One SNS solve's answer, the solver's own (the next solve overwrites it): each read "
      "of an array field returns a new array.",
      "False: a level's scale is outside [SCALE_LOW, SCALE_HIGH] or the bounds are "
      "malformed; nothing solved",
      "‖√w ∘ (A_i x − b_i)‖ per level (the bounds level: the bounds' violation)")
      .def_prop_ro("task_scaling", [](const SnsResult& r) { return copy1(r.task_scaling); },
                   nb::rv_policy::move, "each level's scaling s (the bounds level: 1)")
      .def_prop_ro("margins", [](const SnsResult& r) { return copy1(r.margins); },
                   nb::rv_policy::move, "the unbounded step's rank decision margins")
      .def_prop_ro("ranks", [](const SnsResult& r) { return copy1(r.ranks); },
                   nb::rv_policy::move)
      .def_prop_ro("iterations", [](const SnsResult& r) { return copy1(r.iterations); },
                   nb::rv_policy::move, "the saturation rounds of each level")
      .def_prop_ro("saturated", [](const SnsResult& r) { return copy1(r.saturated); },
                   nb::rv_policy::move,
                   "k × n, flattened: row i begins with level i's saturated columns")
      .def_prop_ro("saturated_count", [](const SnsResult& r) { return copy1(r.saturated_count); },
                   nb::rv_policy::move)
      .def_prop_ro("lower", [](const SnsResult& r) { return copy1(r.lower); },
                   nb::rv_policy::move, "the box the bounds rows give (n)")
      .def_prop_ro("upper", [](const SnsResult& r) { return copy1(r.upper); },
                   nb::rv_policy::move)
      .def_prop_ro("bounds", [](const SnsResult& r) { return static_cast<int>(r.bounds); },
                   "0: the bounds rows are a box; 1: row bad_entry is not a single-column "
                   "row; 2: column bad_entry's bounds do not intersect")
      .def_ro("bad_entry", &SnsResult::bad_entry)
      .def_ro("exact", &SnsResult::exact,
              "every level reached its residual without bounds");

  bind_solver<SnsSolver>(
      m, "SnsSolver",
      "Saturation in the Null Space prepared for one layout (closed_form.hpp): workspaces "
      "allocated here, none per solve. One thread at a time.")
      .def("__init__",
           [](SnsSolver* self, std::vector<Index> starts, Index n, double rcond,
              double bound_tolerance, Index max_saturations, bool bounds_level) {
             prioik::SnsOptions o;
             o.rcond = rcond;
             o.bound_tolerance = bound_tolerance;
             o.max_saturations = max_saturations;
             o.bounds_level = bounds_level;
             new (self) SnsSolver(std::move(starts), n, o);
           },
           nb::arg("starts"), nb::arg("n"), nb::kw_only(), nb::arg("rcond"),
           nb::arg("bound_tolerance") = 1e-9, nb::arg("max_saturations") = -1,
           nb::arg("bounds_level") = false)
      .def("solve", &solve_sns, nb::arg("A").none(), nb::arg("b").none(),
           nb::arg("sqrt_weight").none(), nb::arg("lower").none(), nb::arg("upper").none(),
           nb::rv_policy::reference_internal,
           "Solve one stack (A: M × n, b, sqrt_weight, lower and upper: M; C-contiguous "
           "float64; lower and upper are read on the first level's rows when bounds_level).");
}
