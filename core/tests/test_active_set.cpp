// The active set's own tests, without Python (ctest; `make asan` runs them under
// -fsanitize=address,undefined): equality stacks against the extended Jacobian (the same
// optimum, eq. 18), box-bounded and random inequality stacks solved cold and warm along
// drifting sequences (the same answers; the box held; the equality-first try taken), and
// a malformed layout refused; the certificate (certificate.hpp) passes the solver's clean
// answers and rejects them moved.
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <vector>

#include "prioik/active_set.hpp"
#include "prioik/certificate.hpp"
#include "prioik/extended_jacobian.hpp"
#include "check.hpp"

using prioik::ActiveSetLayout;
using prioik::ActiveSetOptions;
using prioik::ActiveSetSolver;
using prioik::SolveCode;
using I = std::int64_t;

namespace {

/// A stack's rows: A (M × n), targets, bounds, √w, and its layout.
struct Stack {
  ActiveSetLayout layout;
  std::vector<double> A, b, lower, upper, sw;

  void add_level(std::mt19937& rng, I rows, bool box, double target, double bound) {
    std::normal_distribution<double> g;
    std::uniform_real_distribution<double> u(0.2, 1.5);
    const I n = layout.n;
    if (layout.starts.empty()) layout.starts.push_back(0);
    for (I i = 0; i < (box ? n : rows); ++i) {
      for (I c = 0; c < n; ++c) A.push_back(box ? (c == i ? 1.0 : 0.0) : g(rng));
      const bool eq = !box && bound <= 0.0;
      const double t = target * g(rng);
      const double half = box ? u(rng) : bound;
      b.push_back(eq ? t : 0.0);
      lower.push_back(eq ? -INFINITY : (box ? -half : t - half));
      upper.push_back(eq ? INFINITY : (box ? half : t + half));
      sw.push_back(1.0);
      layout.row_eq.push_back(eq ? 1 : 0);
    }
    layout.M = static_cast<I>(b.size());
    layout.starts.push_back(layout.M);
    layout.k = static_cast<I>(layout.starts.size()) - 1;
  }

  void drift(std::mt19937& rng, double scale) {
    std::normal_distribution<double> g;
    for (I j = 0; j < layout.M; ++j) {
      const double s = scale * g(rng);
      if (layout.row_eq[j]) {
        b[j] += s;
      } else if (std::isfinite(lower[j]) && lower[j] != -upper[j]) {
        lower[j] += s;
        upper[j] += s;
      }
    }
  }
};

double distance(const std::vector<double>& a, const std::vector<double>& b) {
  double acc = 0.0, norm = 1.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    acc += (a[i] - b[i]) * (a[i] - b[i]);
    norm = std::fmax(norm, std::fabs(b[i]));
  }
  return std::sqrt(acc) / norm;
}

SolveCode solve(ActiveSetSolver& s, const Stack& st, bool warm) {
  if (warm) {
    const SolveCode first = s.equality_first(st.A.data(), st.b.data(), st.lower.data(),
                                             st.upper.data(), st.sw.data());
    if (first != SolveCode::not_tried) return first;
  }
  return s.solve(st.A.data(), st.b.data(), st.lower.data(), st.upper.data(), st.sw.data());
}

void equality_stacks_give_the_extended_jacobians_answer() {
  std::mt19937 rng(46);
  for (int trial = 0; trial < 40; ++trial) {
    Stack st;
    st.layout.n = 4 + trial % 9;
    const I k = 1 + trial % 4;
    for (I lev = 0; lev < k; ++lev) st.add_level(rng, 1 + (trial + lev) % 5, false, 1.0, 0.0);
    ActiveSetSolver as(st.layout, ActiveSetOptions{});
    const SolveCode code = solve(as, st, false);
    CHECK(code == SolveCode::clean || code == SolveCode::infeasible ||
          code == SolveCode::other);
    prioik::ExtendedJacobianOptions ejo;
    ejo.rcond = 1e-9;
    prioik::ExtendedJacobian ej(st.layout.starts, st.layout.n, ejo);
    const auto& ref = ej.solve(prioik::StackArrays{st.A.data(), st.b.data(), st.sw.data()});
    if (code != SolveCode::other) CHECK(distance(as.result().x, ref.x) <= 1e-9);
  }
}

void inequality_stacks_solve_the_same_cold_and_warm() {
  std::mt19937 rng(47);
  int tried_first = 0;
  for (int seq = 0; seq < 24; ++seq) {
    Stack st;
    st.layout.n = 5 + seq % 12;
    st.add_level(rng, 0, true, 0.0, 0.0);                         // a box |x| ≤ u
    if (seq % 2) st.add_level(rng, 2, false, 1.0, 0.3);           // a band
    for (I lev = 0; lev < 2 + seq % 3; ++lev)
      st.add_level(rng, 1 + (seq + lev) % 4, false, seq % 3 == 0 ? 0.3 : 2.0, 0.0);
    ActiveSetOptions warm_opts;
    ActiveSetOptions cold_opts;
    cold_opts.warm_start = false;
    ActiveSetSolver warm(st.layout, warm_opts), cold(st.layout, cold_opts);
    for (int step = 0; step < 25; ++step) {
      st.drift(rng, 0.02);
      const SolveCode a = solve(warm, st, true);
      const SolveCode b = solve(cold, st, false);
      CHECK(a != SolveCode::not_solved && b != SolveCode::not_solved);
      if (a == SolveCode::other || b == SolveCode::other) continue;
      CHECK(a == b);
      CHECK(distance(warm.result().x, cold.result().x) <= 1e-8);
      tried_first += warm.result().equality_first == 1.0;
      for (I c = 0; c < st.layout.n; ++c)            // the box (level 0) is feasible
        CHECK(std::fabs(warm.result().x[c]) <= st.upper[c] * (1.0 + 1e-9) + 1e-12);
    }
  }
  CHECK(tried_first > 0);
}

void invalid_values_are_not_solved() {
  std::mt19937 rng(48);
  Stack st;
  st.layout.n = 5;
  st.add_level(rng, 0, true, 0.0, 0.0);
  st.add_level(rng, 3, false, 1.0, 0.0);
  ActiveSetSolver s(st.layout, ActiveSetOptions{});
  st.A[7] = NAN;
  CHECK(solve(s, st, true) == SolveCode::not_solved);
  st.A[7] = 0.0;
  st.sw[2] = 0.0;
  CHECK(solve(s, st, false) == SolveCode::not_solved);
}

void a_malformed_layout_is_refused() {
  ActiveSetLayout layout;
  layout.n = 3;
  layout.k = 2;
  layout.M = 2;
  layout.starts = {0, 3, 2};
  layout.row_eq = {1, 1};
  bool threw = false;
  try {
    ActiveSetSolver s(layout, ActiveSetOptions{});
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

void the_certificate_passes_clean_answers_and_rejects_moved_ones() {
  std::mt19937 rng(49);
  std::normal_distribution<double> g;
  int certified = 0;
  for (int seq = 0; seq < 16; ++seq) {
    Stack st;
    st.layout.n = 5 + seq % 10;
    st.add_level(rng, 0, true, 0.0, 0.0);
    if (seq % 2) st.add_level(rng, 2, false, 1.0, 0.3);
    for (I lev = 0; lev < 2 + seq % 3; ++lev)
      st.add_level(rng, 1 + (seq + lev) % 4, false, 2.0, 0.0);
    ActiveSetOptions cold;
    cold.warm_start = false;
    ActiveSetSolver s(st.layout, cold);
    prioik::Certificate cert(st.layout);
    const SolveCode code = solve(s, st, false);
    if (code != SolveCode::clean && code != SolveCode::infeasible) continue;
    std::vector<double> x = s.result().x;
    auto check = [&](const std::vector<double>& at) {
      return cert.check(st.A.data(), st.b.data(), st.lower.data(), st.upper.data(),
                        st.sw.data(), at.data(), true);
    };
    CHECK(check(x) == prioik::CertificateCode::checked);
    CHECK(cert.result().ok);
    CHECK(cert.result().failing_level == -1);
    for (auto& v : x) v += 1e-3 * (1.0 + std::fabs(v)) * g(rng);
    CHECK(check(x) == prioik::CertificateCode::checked);
    CHECK(!cert.result().ok);
    CHECK(cert.result().failing_level >= 0 && cert.result().failing_level <= st.layout.k);
    x[0] = NAN;
    check(x);
    CHECK(!cert.result().ok && cert.result().failing_level == 0);
    ++certified;
    for (auto& a : st.A) a *= 1e120;
    CHECK(check(x) == prioik::CertificateCode::extreme_scale);
  }
  CHECK(certified >= 8);
  ActiveSetLayout bad;
  bad.n = 3;
  bad.k = 2;
  bad.M = 2;
  bad.starts = {0, 3, 2};
  bad.row_eq = {1, 1};
  bool threw = false;
  try {
    prioik::Certificate c(bad);
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

}  // namespace

int main() {
  equality_stacks_give_the_extended_jacobians_answer();
  inequality_stacks_solve_the_same_cold_and_warm();
  invalid_values_are_not_solved();
  a_malformed_layout_is_refused();
  the_certificate_passes_clean_answers_and_rejects_moved_ones();
  if (prioik_test::failures) {
    std::printf("%d failure(s)\n", prioik_test::failures);
    return 1;
  }
  std::printf("active set: all passed\n");
  return 0;
}
