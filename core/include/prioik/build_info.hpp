// What the core was compiled with: the rounding rule and the tuning (core/CMakeLists.txt).
#pragma once

#include <string>

namespace prioik {

struct BuildInfo {
  std::string compiler;   // "GNU 12.2.0"
  std::string eigen;      // Eigen's version, "3.4.1"
  bool native;            // tuned for the building machine (-march=native)
  bool sanitized;         // built with -fsanitize=address,undefined
  bool fast_math;         // compiled with fast math (never: the rounding rule)
  bool fp_contract;       // a * b + c contracted into a fused multiply-add (never: the rounding rule)
  std::string vector_clones;  // the hot functions' clone this CPU runs: "avx2" or "default"
                              // (a portable x86-64 GCC build on Linux), else "none"
};

// The flags this library was compiled with, as the compiler saw them.
BuildInfo build_info();

}  // namespace prioik
