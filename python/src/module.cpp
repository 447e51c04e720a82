// The compiled part of the Python package (bouncecal._core). The pure-Python package
// (python/bouncecal/__init__.py) gives each function its keyword arguments and passes the ones
// the caller set as a dict of option names (the CLI's flags in snake_case); this file turns them
// into the library's inputs, calls the library and returns the result as the CLI's JSON would
// read (json_to_python.cpp). bouncecal::Error becomes a bouncecal.Error subclass carrying the
// message, the code's name and the exit code (errors.cpp).
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.hpp"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "bouncecal's C++ library (use the `bouncecal` package, not this module)";
  m.attr("version") = BOUNCECAL_VERSION;
  bouncecal::python::RegisterErrorTranslator();
  bouncecal::python::BindTools(m);
  bouncecal::python::BindRecordings(m);
  bouncecal::python::BindLive(m);
}
