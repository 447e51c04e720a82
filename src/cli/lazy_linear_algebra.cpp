// Ceres's sparse and LAPACK back ends (CHOLMOD, CXSparse, LAPACK), loaded on first use.
//
// Ceres is linked statically and references these libraries from the solvers that use them
// (sparse Cholesky, LAPACK-backed dense factorisations). The fit never selects those solvers
// (src/fit/solver_options.hpp: DENSE_QR with Eigen's QR), yet linking the libraries loaded
// them into every bouncecal process and, through them, the machine's BLAS. With Debian's
// OpenBLAS 0.3.21 that is 15 of the 39 shared objects, 14 400 of the 22 100 symbol relocations
// at start-up, and one thread per further core spinning in sched_yield until a timeout of 2^28
// CPU cycles (blas_thread_server in driver/others/blas_server.c). Measured without them
// (bench_simulate --processes, median of 11): `bouncecal --version` 30 ms CPU instead of 46 ms.
// openblas_set_num_threads(1) early in main would not have stopped the spinning: it lowers the
// count later calls use; the threads the library's constructor started keep spinning.
//
// So the program does not link them (cmake/lazy_ceres_backends.cmake): each entry point Ceres
// references is defined here and forwards to the real function, which the first call finds
// with dlopen by the library's soname (taken from the library at configure time). The
// executable does not export these definitions, so the real libraries, once loaded, still call
// their own functions. A missing entry point fails the link; a library that cannot be loaded at
// run time ends the program with a message, as the dynamic loader would have at start-up.
// tests/lazy_linear_algebra_test.cpp solves through every back end with these forwarders.
#include <dlfcn.h>

#include <cholmod.h>
#include <cs.h>

#include <cstdio>
#include <cstdlib>
#include <type_traits>

namespace {

// The address of `name` in the library with this soname, loaded on the first call.
void* LoadSymbol(const char* soname, const char* name) {
  void* library = dlopen(soname, RTLD_NOW | RTLD_LOCAL);
  void* symbol = library != nullptr ? dlsym(library, name) : nullptr;
  if (symbol == nullptr) {
    const char* reason = dlerror();
    std::fprintf(stderr, "bouncecal: internal error: Ceres needs %s from %s: %s\n", name, soname,
                 reason != nullptr ? reason : "not found");
    std::abort();
  }
  return symbol;
}

// The real function behind the forwarder kForwarder (same signature), found once per process.
template <auto& kForwarder>
auto& Real(const char* soname, const char* name) {
  using Function = std::remove_reference_t<decltype(kForwarder)>;
  static Function* const real = reinterpret_cast<Function*>(LoadSymbol(soname, name));
  return *real;
}

constexpr const char* kCholmod = BOUNCECAL_CHOLMOD_SONAME;
constexpr const char* kCxsparse = BOUNCECAL_CXSPARSE_SONAME;
constexpr const char* kLapack = BOUNCECAL_LAPACK_SONAME;

}  // namespace

// LAPACK (Fortran calling convention: every argument by address). Reference LAPACK 3.x:
// DPOTRF/DPOTRS (Cholesky), DGEQRF/DORMQR (QR), DTRTRS (triangular solve).
extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda,
             double* b, const int* ldb, int* info);
void dgeqrf_(const int* m, const int* n, double* a, const int* lda, double* tau, double* work,
             const int* lwork, int* info);
void dormqr_(const char* side, const char* trans, const int* m, const int* n, const int* k,
             double* a, const int* lda, double* tau, double* c, const int* ldc, double* work,
             const int* lwork, int* info);
void dtrtrs_(const char* uplo, const char* trans, const char* diag, const int* n, const int* nrhs,
             double* a, const int* lda, double* b, const int* ldb, int* info);
}

void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info) {
  Real<dpotrf_>(kLapack, __func__)(uplo, n, a, lda, info);
}
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda,
             double* b, const int* ldb, int* info) {
  Real<dpotrs_>(kLapack, __func__)(uplo, n, nrhs, a, lda, b, ldb, info);
}
void dgeqrf_(const int* m, const int* n, double* a, const int* lda, double* tau, double* work,
             const int* lwork, int* info) {
  Real<dgeqrf_>(kLapack, __func__)(m, n, a, lda, tau, work, lwork, info);
}
void dormqr_(const char* side, const char* trans, const int* m, const int* n, const int* k,
             double* a, const int* lda, double* tau, double* c, const int* ldc, double* work,
             const int* lwork, int* info) {
  Real<dormqr_>(kLapack, __func__)(side, trans, m, n, k, a, lda, tau, c, ldc, work, lwork, info);
}
void dtrtrs_(const char* uplo, const char* trans, const char* diag, const int* n, const int* nrhs,
             double* a, const int* lda, double* b, const int* ldb, int* info) {
  Real<dtrtrs_>(kLapack, __func__)(uplo, trans, diag, n, nrhs, a, lda, b, ldb, info);
}

// CHOLMOD (declared in cholmod.h, which gives them C linkage).
int cholmod_start(cholmod_common* common) {
  return Real<cholmod_start>(kCholmod, __func__)(common);
}
int cholmod_finish(cholmod_common* common) {
  return Real<cholmod_finish>(kCholmod, __func__)(common);
}
int cholmod_print_common(const char* name, cholmod_common* common) {
  return Real<cholmod_print_common>(kCholmod, __func__)(name, common);
}
int cholmod_amd(cholmod_sparse* a, int* fset, size_t fsize, int* perm, cholmod_common* common) {
  return Real<cholmod_amd>(kCholmod, __func__)(a, fset, fsize, perm, common);
}
int cholmod_camd(cholmod_sparse* a, int* fset, size_t fsize, int* cmember, int* perm,
                 cholmod_common* common) {
  return Real<cholmod_camd>(kCholmod, __func__)(a, fset, fsize, cmember, perm, common);
}
cholmod_factor* cholmod_analyze(cholmod_sparse* a, cholmod_common* common) {
  return Real<cholmod_analyze>(kCholmod, __func__)(a, common);
}
cholmod_factor* cholmod_analyze_p(cholmod_sparse* a, int* user_perm, int* fset, size_t fsize,
                                  cholmod_common* common) {
  return Real<cholmod_analyze_p>(kCholmod, __func__)(a, user_perm, fset, fsize, common);
}
int cholmod_factorize(cholmod_sparse* a, cholmod_factor* l, cholmod_common* common) {
  return Real<cholmod_factorize>(kCholmod, __func__)(a, l, common);
}
cholmod_dense* cholmod_solve(int sys, cholmod_factor* l, cholmod_dense* b, cholmod_common* common) {
  return Real<cholmod_solve>(kCholmod, __func__)(sys, l, b, common);
}
cholmod_sparse* cholmod_triplet_to_sparse(cholmod_triplet* t, size_t nzmax,
                                          cholmod_common* common) {
  return Real<cholmod_triplet_to_sparse>(kCholmod, __func__)(t, nzmax, common);
}
cholmod_dense* cholmod_zeros(size_t nrow, size_t ncol, int xtype, cholmod_common* common) {
  return Real<cholmod_zeros>(kCholmod, __func__)(nrow, ncol, xtype, common);
}
int cholmod_free_dense(cholmod_dense** x, cholmod_common* common) {
  return Real<cholmod_free_dense>(kCholmod, __func__)(x, common);
}
int cholmod_free_factor(cholmod_factor** l, cholmod_common* common) {
  return Real<cholmod_free_factor>(kCholmod, __func__)(l, common);
}
int cholmod_free_sparse(cholmod_sparse** a, cholmod_common* common) {
  return Real<cholmod_free_sparse>(kCholmod, __func__)(a, common);
}

// CXSparse, int/double version (declared in cs.h, C linkage). Memory that Ceres allocates with
// cs_di_malloc is freed inside CXSparse: both go to the same library.
void* cs_di_malloc(int n, size_t size) { return Real<cs_di_malloc>(kCxsparse, __func__)(n, size); }
void* cs_di_calloc(int n, size_t size) { return Real<cs_di_calloc>(kCxsparse, __func__)(n, size); }
void* cs_di_free(void* p) { return Real<cs_di_free>(kCxsparse, __func__)(p); }
cs_di* cs_di_spfree(cs_di* a) { return Real<cs_di_spfree>(kCxsparse, __func__)(a); }
cs_dis* cs_di_sfree(cs_dis* s) { return Real<cs_di_sfree>(kCxsparse, __func__)(s); }
cs_din* cs_di_nfree(cs_din* n) { return Real<cs_di_nfree>(kCxsparse, __func__)(n); }
cs_di* cs_di_compress(const cs_di* t) { return Real<cs_di_compress>(kCxsparse, __func__)(t); }
cs_di* cs_di_transpose(const cs_di* a, int values) {
  return Real<cs_di_transpose>(kCxsparse, __func__)(a, values);
}
cs_di* cs_di_multiply(const cs_di* a, const cs_di* b) {
  return Real<cs_di_multiply>(kCxsparse, __func__)(a, b);
}
cs_di* cs_di_symperm(const cs_di* a, const int* pinv, int values) {
  return Real<cs_di_symperm>(kCxsparse, __func__)(a, pinv, values);
}
int* cs_di_amd(int order, const cs_di* a) { return Real<cs_di_amd>(kCxsparse, __func__)(order, a); }
int* cs_di_etree(const cs_di* a, int ata) { return Real<cs_di_etree>(kCxsparse, __func__)(a, ata); }
int* cs_di_post(const int* parent, int n) {
  return Real<cs_di_post>(kCxsparse, __func__)(parent, n);
}
int* cs_di_counts(const cs_di* a, const int* parent, const int* post, int ata) {
  return Real<cs_di_counts>(kCxsparse, __func__)(a, parent, post, ata);
}
int* cs_di_pinv(const int* p, int n) { return Real<cs_di_pinv>(kCxsparse, __func__)(p, n); }
double cs_di_cumsum(int* p, int* c, int n) {
  return Real<cs_di_cumsum>(kCxsparse, __func__)(p, c, n);
}
cs_dis* cs_di_schol(int order, const cs_di* a) {
  return Real<cs_di_schol>(kCxsparse, __func__)(order, a);
}
cs_din* cs_di_chol(const cs_di* a, const cs_dis* s) {
  return Real<cs_di_chol>(kCxsparse, __func__)(a, s);
}
int cs_di_cholsol(int order, const cs_di* a, double* b) {
  return Real<cs_di_cholsol>(kCxsparse, __func__)(order, a, b);
}
int cs_di_lsolve(const cs_di* l, double* x) {
  return Real<cs_di_lsolve>(kCxsparse, __func__)(l, x);
}
int cs_di_ltsolve(const cs_di* l, double* x) {
  return Real<cs_di_ltsolve>(kCxsparse, __func__)(l, x);
}
int cs_di_pvec(const int* p, const double* b, double* x, int n) {
  return Real<cs_di_pvec>(kCxsparse, __func__)(p, b, x, n);
}
int cs_di_ipvec(const int* p, const double* b, double* x, int n) {
  return Real<cs_di_ipvec>(kCxsparse, __func__)(p, b, x, n);
}
