#include "prioik/build_info.hpp"

#include <Eigen/Core>

#include "vector_clones.hpp"

namespace prioik {

namespace {

// a*b + c with a*b = 1 - 2^-60, which rounds to 1: 0 when the product is rounded first
// (as written), -2^-60 when the compiler contracted the expression into a fused
// multiply-add. volatile: the compiler cannot fold it at compile time.
bool contracts_multiply_add() {
  volatile double a = 1.0 + 0x1p-30, b = 1.0 - 0x1p-30, c = -1.0;
  double x = a, y = b, z = c;
  return x * y + z != 0.0;
}

}  // namespace

BuildInfo build_info() {
  BuildInfo info;
  info.compiler = PRIOIK_COMPILER;
  info.eigen = std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) +
               "." + std::to_string(EIGEN_MINOR_VERSION);
  info.native = PRIOIK_NATIVE_BUILD;
  info.sanitized = PRIOIK_SANITIZE_BUILD;
#if defined(__FAST_MATH__)
  info.fast_math = true;
#else
  info.fast_math = false;
#endif
  info.fp_contract = contracts_multiply_add();
#if PRIOIK_HAS_VECTOR_CLONES
  info.vector_clones = __builtin_cpu_supports("avx2") ? "avx2" : "default";
#else
  info.vector_clones = "none";
#endif
  return info;
}

}  // namespace prioik
