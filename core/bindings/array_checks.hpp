// The array checks of prioik._core's bindings, one helper per kind of argument (input,
// output, stack_input, optional_output; module.cpp, closed_form.cpp), and the numpy
// fields active_set.cpp, rows.cpp and control_step.cpp read directly: each entry point
// takes a float64 (or int64) numpy-compatible array on the CPU, C-contiguous, of the
// layout's shape and not empty; anything else raises prioik::InputError naming the array
// (CoreInputError in Python), never a copy, never a crash. An exact numpy.ndarray that
// passes is read from its fields (a few loads); any other array, or one that does not
// pass, goes through nanobind's ndarray (DLPack), which reads it or names what is wrong.
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

// NumPy's array and dtype structs, their leading fields (numpy/ndarraytypes.h:
// PyArrayObject_fields, PyArray_Descr; public and the same from NumPy 1.7 through 2.x),
// for the bindings that read a numpy.ndarray argument's fields directly (active_set.cpp,
// rows.cpp, control_step.cpp)
struct NumpyArrayFields {
  PyObject_HEAD
  char* data;
  int nd;
  Py_ssize_t* dimensions;
  Py_ssize_t* strides;
  PyObject* base;
  PyObject* descr;
  int flags;
};

struct NumpyDescrFields {
  PyObject_HEAD
  PyTypeObject* typeobj;
  char kind;
  char type;
  char byteorder;
};

constexpr int kNumpyAligned = 0x0100;    // NPY_ARRAY_ALIGNED
constexpr int kNumpyWriteable = 0x0400;  // NPY_ARRAY_WRITEABLE

// Whether a numpy dtype's fields name T's type, float64 ('d') or int64 ('l' where a long
// is 64 bits, 'q'), in the machine's byte order.
template <class T>
bool numpy_dtype_is(const NumpyDescrFields& d) {
  constexpr char own_order = PY_LITTLE_ENDIAN ? '<' : '>';
  if (d.byteorder != '=' && d.byteorder != own_order) return false;
  if (std::is_same_v<std::remove_const_t<T>, double>) return d.kind == 'f' && d.type == 'd';
  return d.kind == 'i' && (d.type == 'q' || (d.type == 'l' && sizeof(long) == 8));
}

// numpy.ndarray, numpy.empty and the float64 and int64 dtypes, looked up once (the
// module's initialisation calls get() first, under the import's GIL). ndarray is null
// unless NumpyArrayFields reads a (2, 3) float64 array of numpy's as it is: every array
// then goes through nanobind's ndarray.
struct NumpyHandles {
  PyTypeObject* ndarray = nullptr;
  PyObject* empty = nullptr;
  PyObject* float64 = nullptr;
  PyObject* int64 = nullptr;

  static const NumpyHandles& get() {
    static const NumpyHandles handles = [] {
      NumpyHandles h;
      try {
        nb::module_ numpy = nb::module_::import_("numpy");
        nb::object probe = numpy.attr("zeros")(nb::make_tuple(2, 3));
        const auto* a = reinterpret_cast<const NumpyArrayFields*>(probe.ptr());
        if (a->nd != 2 || a->dimensions[0] != 2 || a->dimensions[1] != 3 ||
            a->strides[0] != 24 || a->strides[1] != 8 || !(a->flags & kNumpyWriteable) ||
            !numpy_dtype_is<double>(*reinterpret_cast<const NumpyDescrFields*>(a->descr)))
          return h;
        // references held for good (released, never dropped at exit)
        nb::object ndarray = numpy.attr("ndarray"), empty = numpy.attr("empty");
        nb::object float64 = numpy.attr("dtype")("float64"), int64 = numpy.attr("dtype")("int64");
        h.ndarray = reinterpret_cast<PyTypeObject*>(ndarray.release().ptr());
        h.empty = empty.release().ptr();
        h.float64 = float64.release().ptr();
        h.int64 = int64.release().ptr();
      } catch (const nb::python_error&) {
        h = NumpyHandles{};
      }
      return h;
    }();
    return handles;
  }
};

// InputError naming `name` unless `data` is aligned for T (a numpy view of packed bytes
// may not be: reading it is undefined behaviour)
template <class T>
void require_aligned(const void* data, const char* name) {
  if (reinterpret_cast<std::uintptr_t>(data) % alignof(T) != 0)
    throw prioik::InputError(std::string(name) + " is not aligned (a view of packed bytes)");
}

// The data of `h` read from its fields when it is exactly a numpy.ndarray of T's dtype
// (float64 or int64, native byte order), aligned, writable unless T is const,
// C-contiguous and of `shape` (-1: any extent) with no extent 0 (`got` receives the
// shape); else nullptr, and the caller reads it the general way. No Python call: the
// common argument costs a few loads where nanobind's DLPack import calls __dlpack__.
template <class T>
T* numpy_fields_data(nb::handle h, std::initializer_list<Index> shape, Index* got) {
  static_assert(sizeof(T) == 8, "float64 or int64 elements");
  PyTypeObject* ndarray = NumpyHandles::get().ndarray;
  if (ndarray == nullptr || Py_TYPE(h.ptr()) != ndarray) return nullptr;
  const auto* a = reinterpret_cast<const NumpyArrayFields*>(h.ptr());
  const int need = kNumpyAligned | (std::is_const_v<T> ? 0 : kNumpyWriteable);
  if ((a->flags & need) != need || a->nd != static_cast<int>(shape.size()) ||
      !numpy_dtype_is<T>(*reinterpret_cast<const NumpyDescrFields*>(a->descr)))
    return nullptr;
  int d = 0;
  for (Index want : shape) {
    const Index extent = static_cast<Index>(a->dimensions[d++]);
    if (extent == 0 || (want >= 0 && extent != want)) return nullptr;
  }
  Py_ssize_t expect = sizeof(T);   // C order: each stride the product of the items after it
  for (d = a->nd - 1; d >= 0; --d) {
    if (a->dimensions[d] > 1 && a->strides[d] != expect) return nullptr;
    expect *= a->dimensions[d];
  }
  if (got != nullptr)
    for (d = 0; d < a->nd; ++d) got[d] = static_cast<Index>(a->dimensions[d]);
  return reinterpret_cast<T*>(a->data);
}

// The data of `h` as a C-contiguous, aligned array of T of `shape` (-1: any extent > 0;
// an output is writable), or InputError naming `name`. `got` receives the shape.
template <class T, class Array>
T* checked(nb::handle h, const char* name, std::initializer_list<Index> shape,
           Index* got = nullptr) {
  if (T* data = numpy_fields_data<T>(h, shape, got)) return data;
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
  require_aligned<T>(a.data(), name);
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

// A stack's arrays of a layout of M rows and n columns: A (M × n), b and sqrt_weight (M)
inline StackArrays stack_input(nb::handle A, nb::handle b, nb::handle w, Index M, Index n) {
  return StackArrays{input(A, "A", {M, n}), input(b, "b", {M}), input(w, "sqrt_weight", {M})};
}

// An answer's optional output `name` of `size` entries: nullptr when h is None
template <class T>
T* optional_output(nb::handle h, const char* name, Index size) {
  return h.is_none() ? nullptr : output<T>(h, name, {size});
}

// out = v, when out is given (optional_output)
template <class T>
void copy_out(const std::vector<T>& v, T* out) {
  if (out != nullptr) std::copy(v.begin(), v.end(), out);
}

// a new numpy array holding a copy of v (the caller keeps it; the next solve leaves it)
template <class T>
nb::ndarray<nb::numpy, T, nb::ndim<1>> copy1(const std::vector<T>& v) {
  T* data = new T[v.size()];
  std::copy(v.begin(), v.end(), data);
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
  return nb::ndarray<nb::numpy, T, nb::ndim<1>>(data, {v.size()}, owner);
}

// a new numpy array holding a copy of v (the caller keeps it; the next solve leaves it):
// numpy.empty's array filled through its fields, ~0.2 us where copy1's export copies a
// buffer view through numpy.copy (~0.8 us); copy1 when numpy's fields are not read. Its
// getter takes rv_policy::automatic: the array is returned as it is (move would copy it
// again; reference_internal refuses copy1's owned array).
template <class T>
nb::ndarray<nb::numpy, T, nb::ndim<1>> numpy_copy1(const std::vector<T>& v) {
  const NumpyHandles& numpy = NumpyHandles::get();
  static_assert(sizeof(T) == 8, "float64 or int64 elements");
  if (numpy.ndarray != nullptr && !v.empty()) {
    nb::object size = nb::int_(v.size());
    PyObject* args[] = {size.ptr(), std::is_same_v<T, double> ? numpy.float64 : numpy.int64};
    nb::object array = nb::steal(PyObject_Vectorcall(numpy.empty, args, 2, nullptr));
    if (!array.is_valid()) throw nb::python_error();
    if (T* data = numpy_fields_data<T>(array, {static_cast<Index>(v.size())}, nullptr)) {
      std::copy(v.begin(), v.end(), data);
      return nb::cast<nb::ndarray<nb::numpy, T, nb::ndim<1>>>(array);
    }
  }
  return copy1(v);
}

}  // namespace prioik::bindings
