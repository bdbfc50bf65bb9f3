// prioik._lexls: a binding of lexls (Dimitrov, Sherikov & Wieber 2015; header-only C++
// over Eigen, BSD-2), the peer an exact inequality solver is compared with. Built only
// when its headers are found (core/CMakeLists.txt: PRIOIK_LEXLS_DIR). Not part of the
// core: it serves the `lexls` formulation plugin and the benchmarks.
//
// One LexlsSolver per prepared layout (its level sizes); each solve builds a lexls
// `LexLSI` as lexls is used (a new problem per solve: lexls's reset() cannot clear a
// hot start), sets every level as a general objective `lower ≤ A x − w ≤ upper`, and
// solves; a hot start is lexls's: `set_x0` with the previous x plus `api_activate` of
// the previous working set (rows held at a bound; equality rows are lexls's own).
// Inputs are checked here (float64, shape, C-contiguous, finite A, no NaN bound,
// lower ≤ upper) and a bad one raises prioik's CoreInputError naming it.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <lexls/lexlsi.h>

#include "prioik/extended_jacobian.hpp"   // prioik::InputError

namespace nb = nanobind;

namespace {

using I64 = std::int64_t;
using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ROArray = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using ROMatrix = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

/// lexls's stand-in for an infinite bound (its phase 1 needs finite numbers).
constexpr double kInfinity = 1e30;

[[noreturn]] void bad(const std::string& message) { throw prioik::InputError(message); }

/// The outcome of one lexls solve, read by name.
/// (x: LexlsSolver.x, the solver's own vector, overwritten by the next solve)
struct LexlsResult {
    int termination = -1;          ///< lexls::TerminationStatus
    I64 factorizations = 0;        ///< lexls's count (its cap: max_factorizations)
    I64 active = 0;                ///< rows in the final working set
    bool hot_started = false;
};

class LexlsSolver {
public:
    LexlsSolver(I64 n, std::vector<I64> level_rows, I64 max_factorizations,
                double tol_linear_dependence)
        : n_(n), rows_(std::move(level_rows)) {
        if (n_ <= 0) bad("lexls: n must be positive, got " + std::to_string(n_));
        if (rows_.empty()) bad("lexls: level_rows is empty");
        for (size_t i = 0; i < rows_.size(); ++i) {
            if (rows_[i] <= 0)
                bad("lexls: level_rows[" + std::to_string(i) + "] must be positive, got " +
                    std::to_string(rows_[i]));
            start_.push_back(m_);
            m_ += rows_[i];
        }
        if (max_factorizations <= 0) bad("lexls: max_factorizations must be positive");
        if (!(tol_linear_dependence > 0) || !std::isfinite(tol_linear_dependence))
            bad("lexls: tol_linear_dependence must be a finite number > 0");
        params_.setDefaults();
        params_.max_number_of_factorizations = static_cast<int>(max_factorizations);
        params_.tol_linear_dependence = tol_linear_dependence;
        dims_.assign(rows_.begin(), rows_.end());
        types_.assign(rows_.size(), LexLS::GENERAL_OBJECTIVE);
        for (I64 r : rows_) data_.emplace_back(Matrix::Zero(r, n_ + 2));
        x_prev_ = Eigen::VectorXd::Zero(n_);
        working_.assign(rows_.size(), {});
    }

    /// Solve `lower ≤ A x − w ≤ upper` level by level (rows stacked by level);
    /// `hot_start`: from the previous solve's x and working set (a cold solve when
    /// there is none).
    LexlsResult solve(nb::handle A_, nb::handle lower_, nb::handle upper_, bool hot_start) {
        const double* A = matrix(A_, "A");
        const double* lower = vector(lower_, "lower");
        const double* upper = vector(upper_, "upper");
        for (size_t i = 0; i < rows_.size(); ++i) {
            Matrix& d = data_[i];
            for (I64 r = 0; r < rows_[i]; ++r) {
                const I64 row = start_[i] + r;
                for (I64 j = 0; j < n_; ++j) {
                    const double a = A[row * n_ + j];
                    if (!std::isfinite(a))
                        bad("lexls: A[" + std::to_string(row) + ", " + std::to_string(j) +
                            "] is not finite");
                    d(r, j) = a;
                }
                const double lo = lower[row], up = upper[row];
                if (std::isnan(lo) || std::isnan(up))
                    bad("lexls: lower/upper[" + std::to_string(row) + "] is NaN");
                if (lo > up)
                    bad("lexls: lower[" + std::to_string(row) + "] > upper[" +
                        std::to_string(row) + "]");
                d(r, n_) = std::max(lo, -kInfinity);
                d(r, n_ + 1) = std::min(up, kInfinity);
            }
        }
        LexLS::internal::LexLSI solver(static_cast<LexLS::Index>(n_),
                                       static_cast<LexLS::Index>(rows_.size()),
                                       dims_.data(), types_.data());
        solver.setParameters(params_);
        for (size_t i = 0; i < rows_.size(); ++i)
            solver.setData(static_cast<LexLS::Index>(i), data_[i]);
        LexlsResult out;
        if (hot_start && solved_) {
            solver.set_x0(x_prev_);
            for (size_t i = 0; i < rows_.size(); ++i)
                for (I64 r = 0; r < rows_[i]; ++r) {
                    const auto type = working_[i][r];
                    if (type == LexLS::CTR_ACTIVE_LB || type == LexLS::CTR_ACTIVE_UB)
                        solver.api_activate(static_cast<LexLS::Index>(i),
                                            static_cast<LexLS::Index>(r), type);
                }
            out.hot_started = true;
        }
        LexLS::TerminationStatus status;
        {
            nb::gil_scoped_release release;
            status = solver.solve();
        }
        out.termination = static_cast<int>(status);
        out.factorizations = static_cast<I64>(solver.getFactorizationsCount());
        out.active = static_cast<I64>(solver.getActiveCtrCount());
        x_prev_ = solver.get_x();   // (same size: no allocation)
        for (size_t i = 0; i < rows_.size(); ++i)
            solver.getActiveCtr(static_cast<LexLS::Index>(i), working_[i]);
        solved_ = true;
        return out;
    }

    /// Forget the previous solve: the next one is cold.
    void reset() { solved_ = false; }

    /// The last solve's x (a view of the solver's vector: copy it to keep it).
    nb::ndarray<nb::numpy, double, nb::ndim<1>> x() {
        return nb::ndarray<nb::numpy, double, nb::ndim<1>>(x_prev_.data(),
                                                           {static_cast<size_t>(n_)});
    }
    I64 n() const { return n_; }
    I64 m() const { return m_; }

private:
    const double* matrix(nb::handle h, const char* name) const {
        ROMatrix a;
        if (!nb::try_cast(h, a, false))
            bad(std::string("lexls: ") + name + " must be a C-contiguous float64 matrix");
        if (static_cast<I64>(a.shape(0)) != m_ || static_cast<I64>(a.shape(1)) != n_)
            bad(std::string("lexls: ") + name + " must have shape (" + std::to_string(m_) +
                ", " + std::to_string(n_) + ")");
        return a.data();
    }
    const double* vector(nb::handle h, const char* name) const {
        ROArray a;
        if (!nb::try_cast(h, a, false))
            bad(std::string("lexls: ") + name + " must be a C-contiguous float64 vector");
        if (static_cast<I64>(a.shape(0)) != m_)
            bad(std::string("lexls: ") + name + " must have shape (" + std::to_string(m_) +
                ",)");
        return a.data();
    }

    I64 n_ = 0, m_ = 0;
    std::vector<I64> rows_, start_;
    std::vector<LexLS::Index> dims_;
    std::vector<LexLS::ObjectiveType> types_;
    std::vector<Matrix> data_;
    LexLS::ParametersLexLSI params_;
    Eigen::VectorXd x_prev_;
    std::vector<std::vector<LexLS::ConstraintActivationType>> working_;
    bool solved_ = false;
};

}  // namespace

NB_MODULE(_lexls, m) {
    m.doc() = "lexls (Dimitrov, Sherikov & Wieber 2015), bound for prioik's lexls plugin";
    nb::module_::import_("prioik._core");   // CoreInputError's translator
    nb::register_exception_translator([](const std::exception_ptr& p, void*) {
        try {
            std::rethrow_exception(p);
        } catch (const prioik::InputError& e) {
            nb::object err = nb::module_::import_("prioik.formulations.base")
                                 .attr("CoreInputError");
            PyErr_SetString(err.ptr(), e.what());
        } catch (const LexLS::Exception& e) {
            nb::object err = nb::module_::import_("prioik.formulations.base")
                                 .attr("FormulationError");
            PyErr_SetString(err.ptr(), (std::string("lexls: ") + e.what()).c_str());
        }
    });
    nb::class_<LexlsResult>(m, "LexlsResult")
        .def_ro("termination", &LexlsResult::termination)
        .def_ro("factorizations", &LexlsResult::factorizations)
        .def_ro("active", &LexlsResult::active)
        .def_ro("hot_started", &LexlsResult::hot_started);
    nb::class_<LexlsSolver>(m, "LexlsSolver")
        .def(nb::init<I64, std::vector<I64>, I64, double>(), nb::arg("n"),
             nb::arg("level_rows"), nb::arg("max_factorizations") = 200,
             nb::arg("tol_linear_dependence") = 1e-12)
        .def("solve", &LexlsSolver::solve, nb::arg("A"), nb::arg("lower"), nb::arg("upper"),
             nb::arg("hot_start") = false)
        .def("reset", &LexlsSolver::reset)
        .def_prop_ro("x", &LexlsSolver::x, nb::rv_policy::reference_internal)
        .def_prop_ro("n", &LexlsSolver::n)
        .def_prop_ro("m", &LexlsSolver::m);
    m.attr("PROBLEM_SOLVED") = static_cast<int>(LexLS::PROBLEM_SOLVED);
    m.attr("PROBLEM_SOLVED_CYCLING_HANDLING") =
        static_cast<int>(LexLS::PROBLEM_SOLVED_CYCLING_HANDLING);
    m.attr("MAX_NUMBER_OF_FACTORIZATIONS_EXCEEDED") =
        static_cast<int>(LexLS::MAX_NUMBER_OF_FACTORIZATIONS_EXCEEDED);
}
