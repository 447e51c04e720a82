// bouncecal/io/provenance.hpp — where a result came from: input checksums, version, date.
//
// Every parameter file records the SHA-256 of each input recording, the bouncecal version,
// the options and the UTC date, so a fitted damping can be traced back to the exact audio.
//
//   Provenance p = MakeProvenance({"drop.wav"});    // throws Error(kInputMissing) naming the file
//   p.inputs[0].sha256;                              // 64 lowercase hex digits
#pragma once

#include <ctime>
#include <string>
#include <vector>

namespace bouncecal {

struct InputFile {
  std::string path;
  std::string sha256;  // lowercase hex; "" for standard input ("-")
};

struct Provenance {
  std::vector<InputFile> inputs;
  std::string bouncecal_version;
  std::string date_utc;  // ISO 8601, "2026-11-22T04:20:03Z"
};

// SHA-256 of a file's bytes (OpenSSL EVP), lowercase hex. Throws Error(kInputMissing) when the
// file cannot be opened or read.
std::string Sha256OfFile(const std::string& path);
// SHA-256 of a byte string, lowercase hex.
std::string Sha256OfString(const std::string& bytes);
// ISO 8601 UTC date of a time point ("YYYY-MM-DDTHH:MM:SSZ").
std::string IsoDateUtc(std::time_t t);
// The current UTC date.
std::string NowIsoDateUtc();
// The library version (CMake project version).
std::string BouncecalVersion();
// Checksums of every input plus version and current date. Standard input ("-"), read once by
// the reader, is not checksummed: its sha256 is "".
inline constexpr const char* kStandardInput = "-";
Provenance MakeProvenance(const std::vector<std::string>& input_paths);

}  // namespace bouncecal
