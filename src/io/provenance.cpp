#include "bouncecal/io/provenance.hpp"

#include <openssl/evp.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <memory>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

struct MdCtxDeleter {
  void operator()(EVP_MD_CTX* c) const { EVP_MD_CTX_free(c); }
};
using MdCtx = std::unique_ptr<EVP_MD_CTX, MdCtxDeleter>;

MdCtx NewSha256() {
  MdCtx ctx(EVP_MD_CTX_new());
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1) {
    throw Error(ErrorCode::kInternal, "OpenSSL: cannot initialise SHA-256");
  }
  return ctx;
}

std::string Finish(EVP_MD_CTX* ctx) {
  std::array<unsigned char, EVP_MAX_MD_SIZE> md{};
  unsigned int len = 0;
  if (EVP_DigestFinal_ex(ctx, md.data(), &len) != 1) {
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
    if (n > 0 && EVP_DigestUpdate(ctx.get(), buf.data(), static_cast<size_t>(n)) != 1) {
      throw Error(ErrorCode::kInternal, "OpenSSL: SHA-256 update failed");
    }
  }
  if (in.bad()) throw Error(ErrorCode::kInputMissing, path + ": read error while checksumming");
  return Finish(ctx.get());
}

std::string Sha256OfString(const std::string& bytes) {
  MdCtx ctx = NewSha256();
  if (EVP_DigestUpdate(ctx.get(), bytes.data(), bytes.size()) != 1) {
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
  for (const auto& path : input_paths) p.inputs.push_back({path, Sha256OfFile(path)});
  p.bouncecal_version = BouncecalVersion();
  p.date_utc = NowIsoDateUtc();
  return p;
}

}  // namespace bouncecal
