#include "bouncecal/io/provenance.hpp"

#include <dlfcn.h>
#include <openssl/evp.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <memory>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

// OpenSSL's libcrypto, opened by its soname on the first checksum (not linked: loading it cost
// every process ~1.2 ms at start-up; CMakeLists.txt). The entry points keep the headers' types.
struct Crypto {
  decltype(&EVP_MD_CTX_new) md_ctx_new = nullptr;
  decltype(&EVP_MD_CTX_free) md_ctx_free = nullptr;
  decltype(&EVP_sha256) sha256 = nullptr;
  decltype(&EVP_DigestInit_ex) digest_init = nullptr;
  decltype(&EVP_DigestUpdate) digest_update = nullptr;
  decltype(&EVP_DigestFinal_ex) digest_final = nullptr;
};

template <typename F>
void Find(void* library, const char* name, F* out) {
  void* symbol = dlsym(library, name);
  if (symbol == nullptr)
    throw Error(ErrorCode::kInternal,
                std::string("OpenSSL: ") + BOUNCECAL_CRYPTO_SONAME + " has no " + name);
  *out = reinterpret_cast<F>(symbol);
}

const Crypto& LibCrypto() {
  static const Crypto crypto = [] {
    void* library = dlopen(BOUNCECAL_CRYPTO_SONAME, RTLD_NOW | RTLD_LOCAL);
    if (library == nullptr) {
      const char* why = dlerror();
      throw Error(ErrorCode::kInternal,
                  std::string("OpenSSL: cannot load ") + BOUNCECAL_CRYPTO_SONAME +
                      " for SHA-256: " + (why != nullptr ? why : "not found"));
    }
    Crypto c;
    Find(library, "EVP_MD_CTX_new", &c.md_ctx_new);
    Find(library, "EVP_MD_CTX_free", &c.md_ctx_free);
    Find(library, "EVP_sha256", &c.sha256);
    Find(library, "EVP_DigestInit_ex", &c.digest_init);
    Find(library, "EVP_DigestUpdate", &c.digest_update);
    Find(library, "EVP_DigestFinal_ex", &c.digest_final);
    return c;
  }();
  return crypto;
}

struct MdCtxDeleter {
  void operator()(EVP_MD_CTX* c) const { LibCrypto().md_ctx_free(c); }
};
using MdCtx = std::unique_ptr<EVP_MD_CTX, MdCtxDeleter>;

MdCtx NewSha256() {
  const Crypto& lib = LibCrypto();
  MdCtx ctx(lib.md_ctx_new());
  if (!ctx || lib.digest_init(ctx.get(), lib.sha256(), nullptr) != 1) {
    throw Error(ErrorCode::kInternal, "OpenSSL: cannot initialise SHA-256");
  }
  return ctx;
}

std::string Finish(EVP_MD_CTX* ctx) {
  std::array<unsigned char, EVP_MAX_MD_SIZE> md{};
  unsigned int len = 0;
  if (LibCrypto().digest_final(ctx, md.data(), &len) != 1) {
    throw Error(ErrorCode::kInternal, "OpenSSL: SHA-256 failed");
  }
  static const char* kHex = "0123456789abcdef";
  std::string out;
  out.reserve(2 * len);
  for (unsigned int i = 0; i < len; ++i) {
    out.push_back(kHex[md[i] >> 4]);
    out.push_back(kHex[md[i] & 0xF]);
  }
  return out;
}

}  // namespace

std::string Sha256OfFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot open file for checksum");
  MdCtx ctx = NewSha256();
  std::array<char, 1 << 16> buf{};
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const std::streamsize n = in.gcount();
    if (n > 0 && LibCrypto().digest_update(ctx.get(), buf.data(), static_cast<size_t>(n)) != 1) {
      throw Error(ErrorCode::kInternal, "OpenSSL: SHA-256 update failed");
    }
  }
  if (in.bad()) throw Error(ErrorCode::kInputMissing, path + ": read error while checksumming");
  return Finish(ctx.get());
}

std::string Sha256OfString(const std::string& bytes) {
  MdCtx ctx = NewSha256();
  if (LibCrypto().digest_update(ctx.get(), bytes.data(), bytes.size()) != 1) {
    throw Error(ErrorCode::kInternal, "OpenSSL: SHA-256 update failed");
  }
  return Finish(ctx.get());
}

std::string IsoDateUtc(std::time_t t) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::array<char, 32> buf{};
  std::strftime(buf.data(), buf.size(), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf.data();
}

std::string NowIsoDateUtc() { return IsoDateUtc(std::time(nullptr)); }

std::string BouncecalVersion() { return BOUNCECAL_VERSION; }

Provenance MakeProvenance(const std::vector<std::string>& input_paths) {
  Provenance p;
  for (const auto& path : input_paths)
    p.inputs.push_back({path, path == kStandardInput ? std::string() : Sha256OfFile(path)});
  p.bouncecal_version = BouncecalVersion();
  p.date_utc = NowIsoDateUtc();
  return p;
}

}  // namespace bouncecal
