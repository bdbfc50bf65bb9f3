// prioik._core: the Python bindings of the compiled core (nanobind).
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>

#include "prioik/build_info.hpp"

namespace nb = nanobind;

void bind_active_set(nb::module_& m);

NB_MODULE(_core, m) {
  m.doc() = "prioik's compiled core (C++17): the extended Jacobian's nested pivoted QR.";

  nb::class_<prioik::BuildInfo>(m, "BuildInfo",
                                "What the core was compiled with (core/CMakeLists.txt).")
      .def_ro("compiler", &prioik::BuildInfo::compiler)
      .def_ro("eigen", &prioik::BuildInfo::eigen)
      .def_ro("native", &prioik::BuildInfo::native, "tuned for the building machine")
      .def_ro("sanitized", &prioik::BuildInfo::sanitized)
      .def_ro("fast_math", &prioik::BuildInfo::fast_math)
      .def_ro("fp_contract", &prioik::BuildInfo::fp_contract,
              "a * b + c contracted into a fused multiply-add");
  m.def("build_info", &prioik::build_info, "The flags the core was compiled with.");
  bind_active_set(m);
}
