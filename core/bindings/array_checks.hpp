// The array checks of prioik._core's bindings (module.cpp, closed_form.cpp): each entry
// point takes a float64 (or int64) numpy-compatible array on the CPU, C-contiguous, of
// the layout's shape and not empty; anything else raises prioik::InputError naming the
// array (CoreInputError in Python), never a copy, never a crash.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <type_traits>
#include <vector>

#include "prioik/extended_jacobian.hpp"

namespace prioik::bindings {

namespace nb = nanobind;

using AnyArray = nb::ndarray<nb::ro>;

inline std::string python_type_name(nb::handle h) { return Py_TYPE(h.ptr())->tp_name; }

template <class Array>
inline std::string dtype_text(const Array& a) {
  const nb::dlpack::dtype t = a.dtype();
  const char* kind = "an unknown type";
  switch (static_cast<nb::dlpack::dtype_code>(t.code)) {
    case nb::dlpack::dtype_code::Int: kind = "int"; break;
    case nb::dlpack::dtype_code::UInt: kind = "uint"; break;
    case nb::dlpack::dtype_code::Float: kind = "float"; break;
    case nb::dlpack::dtype_code::Complex: kind = "complex"; break;
    case nb::dlpack::dtype_code::Bool: kind = "bool"; break;
    default: break;
  }
  return std::string(kind) + std::to_string(t.bits);
}

template <class Array>
inline std::string shape_text(const Array& a) {
  std::string s = "(";
  for (size_t i = 0; i < a.ndim(); ++i) s += (i ? ", " : "") + std::to_string(a.shape(i));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

inline std::string expected_text(const std::vector<Index>& shape) {
  std::string s = "(";
  for (size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  return s + (shape.size() == 1 ? ",)" : ")");
}

// The data of `h` as a C-contiguous array of T of `shape` (-1: any extent > 0; an
// output is writable), or InputError naming `name`. `got` receives the shape.
template <class T, class Array>
T* checked(nb::handle h, const char* name, std::initializer_list<Index> shape,
           Index* got = nullptr) {
  Array a;
  if (!nb::try_cast(h, a, false))
    throw prioik::InputError(std::string(name) + " must be a " +
                             (std::is_same_v<std::remove_const_t<T>, double> ? "float64" : "int64") +
                             " numpy array" +
                             (std::is_const_v<T> ? "" : " (writable)") + ", got " +
                             python_type_name(h));
  if (a.dtype() != nb::dtype<std::remove_const_t<T>>())
    throw prioik::InputError(std::string(name) + " must be " +
                             (std::is_same_v<std::remove_const_t<T>, double> ? "float64" : "int64") +
                             ", got " + dtype_text(a));
  if (a.device_type() != nb::device::cpu::value)
    throw prioik::InputError(std::string(name) + " must be on the CPU");
  if (a.ndim() != shape.size())
    throw prioik::InputError(std::string(name) + " must have " + std::to_string(shape.size()) +
                             " dimensions, got shape " + shape_text(a));
  size_t i = 0;
  for (Index want : shape) {
    if (a.shape(i) == 0)
      throw prioik::InputError(std::string(name) + " is empty (shape " + shape_text(a) + ")");
    if (want >= 0 && static_cast<Index>(a.shape(i)) != want)
      throw prioik::InputError(std::string(name) + " must have shape " +
                               expected_text(std::vector<Index>(shape)) + ", got " + shape_text(a));
    if (got != nullptr) got[i] = static_cast<Index>(a.shape(i));
    ++i;
  }
  int64_t expect = 1;
  for (size_t d = shape.size(); d-- > 0;) {
    if (a.shape(d) > 1 && a.stride(d) != expect)
      throw prioik::InputError(std::string(name) + " must be C-contiguous (a view with strides "
                               "is not taken: pass np.ascontiguousarray of it)");
    expect *= static_cast<int64_t>(a.shape(d));
  }
  return static_cast<T*>(a.data());
}

inline const double* input(nb::handle h, const char* name, std::initializer_list<Index> shape,
                    Index* got = nullptr) {
  return checked<const double, nb::ndarray<nb::ro>>(h, name, shape, got);
}

template <class T>
T* output(nb::handle h, const char* name, std::initializer_list<Index> shape) {
  return checked<T, nb::ndarray<>>(h, name, shape);
}

// a new numpy array holding a copy of v (the caller keeps it; the next solve leaves it)
template <class T>
nb::ndarray<nb::numpy, T, nb::ndim<1>> copy1(const std::vector<T>& v) {
  T* data = new T[v.size()];
  std::copy(v.begin(), v.end(), data);
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
  return nb::ndarray<nb::numpy, T, nb::ndim<1>>(data, {v.size()}, owner);
}

}  // namespace prioik::bindings
