# Ceres's sparse and LAPACK back ends, for targets that load them on first use.
#
# Ceres (Debian's static libceres.a) lists SuiteSparse (CHOLMOD, SPQR), CXSparse, LAPACK and
# BLAS in its link interface. Linking them loads them into every process, and through them the
# machine's BLAS: with Debian's OpenBLAS 0.3.21 that is 15 shared objects and 14 400 symbol
# relocations at start-up (a third of `bouncecal --version`'s CPU) and one thread per further
# core that spins in sched_yield until a timeout of 2^28 CPU cycles (driver/others/
# blas_server.c, blas_thread_server and THREAD_TIMEOUT). The fit never calls them
# (src/fit/solver_options.hpp: DENSE_QR with Eigen's QR).
#
# A target with the property BOUNCECAL_LAZY_CERES_BACKENDS set to ON does not link these
# libraries; it compiles src/cli/lazy_linear_algebra.cpp instead, whose functions forward each
# entry point Ceres references to the real library, opened by its soname on the first call.
# Every other target links them as Ceres lists them.
#
# Sets BOUNCECAL_LAZY_BACKEND_DEFINITIONS (the sonames, as compile definitions) and
# BOUNCECAL_LAZY_BACKEND_INCLUDES (the SuiteSparse and CXSparse headers).

# The SONAME recorded in a shared library (what the dynamic loader and dlopen look up).
function(bouncecal_soname library out_var)
  get_filename_component(real ${library} REALPATH)
  execute_process(COMMAND ${CMAKE_OBJDUMP} -p ${real} OUTPUT_VARIABLE dump
                  RESULT_VARIABLE result ERROR_QUIET)
  string(REGEX MATCH "SONAME +([^ \n]+)" match "${dump}")
  if(NOT result EQUAL 0 OR NOT CMAKE_MATCH_1)
    message(FATAL_ERROR "lazy Ceres back ends: no SONAME in ${library} (objdump -p)")
  endif()
  set(${out_var} ${CMAKE_MATCH_1} PARENT_SCOPE)
endfunction()

set(backend_regex "SuiteSparse::|CXSparse::|lapack|blas|atlas")
get_target_property(ceres_links Ceres::ceres INTERFACE_LINK_LIBRARIES)
set(ceres_links_lazy)
foreach(item ${ceres_links})
  if(item MATCHES "${backend_regex}")
    list(APPEND ceres_links_lazy
         "$<$<NOT:$<BOOL:$<TARGET_PROPERTY:BOUNCECAL_LAZY_CERES_BACKENDS>>>:${item}>")
  else()
    list(APPEND ceres_links_lazy ${item})
  endif()
endforeach()
set_target_properties(Ceres::ceres PROPERTIES INTERFACE_LINK_LIBRARIES "${ceres_links_lazy}")

get_target_property(cholmod_library SuiteSparse::CHOLMOD IMPORTED_LOCATION)
get_target_property(cxsparse_library CXSparse::CXSparse IMPORTED_LOCATION)
set(lapack_library ${ceres_links})
list(FILTER lapack_library INCLUDE REGEX "/liblapack[^/]*$")
if(NOT cholmod_library OR NOT cxsparse_library OR NOT lapack_library)
  message(FATAL_ERROR "lazy Ceres back ends: Ceres's link interface changed (CHOLMOD "
                      "'${cholmod_library}', CXSparse '${cxsparse_library}', LAPACK "
                      "'${lapack_library}'); update cmake/lazy_ceres_backends.cmake")
endif()
bouncecal_soname(${cholmod_library} cholmod_soname)
bouncecal_soname(${cxsparse_library} cxsparse_soname)
bouncecal_soname(${lapack_library} lapack_soname)
set(BOUNCECAL_LAZY_BACKEND_DEFINITIONS BOUNCECAL_CHOLMOD_SONAME="${cholmod_soname}"
    BOUNCECAL_CXSPARSE_SONAME="${cxsparse_soname}" BOUNCECAL_LAPACK_SONAME="${lapack_soname}")
get_target_property(cholmod_includes SuiteSparse::CHOLMOD INTERFACE_INCLUDE_DIRECTORIES)
get_target_property(cxsparse_includes CXSparse::CXSparse INTERFACE_INCLUDE_DIRECTORIES)
set(BOUNCECAL_LAZY_BACKEND_INCLUDES ${cholmod_includes} ${cxsparse_includes})
message(STATUS "Ceres back ends loaded on first use by the program: ${cholmod_soname} "
               "${cxsparse_soname} ${lapack_soname}")
