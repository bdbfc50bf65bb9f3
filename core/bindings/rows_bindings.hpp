// prioik._core.rows (bindings/rows.cpp): registered by module.cpp.
#pragma once

#include <nanobind/nanobind.h>

// Adds the submodule `rows` (the robot row writers) to `parent`.
void register_rows(nanobind::module_& parent);
