// The C++ tests' one assertion: CHECK(cond) prints the file, line and condition that
// failed and counts it in prioik_test::failures, which a test program's main reports
// and turns into its exit status (ctest reads it).
#pragma once

#include <cstdio>

namespace prioik_test {

inline int failures = 0;

}  // namespace prioik_test

#define CHECK(cond)                                                          \
  do {                                                                       \
    if (!(cond)) {                                                           \
      std::printf("FAILED %s:%d: %s\n", __FILE__, __LINE__, #cond);          \
      ++prioik_test::failures;                                               \
    }                                                                        \
  } while (0)
