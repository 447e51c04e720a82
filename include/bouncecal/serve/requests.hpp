// bouncecal/serve/requests.hpp — what the server reads from a request before any work: the
// target's path and query, an upload in a multipart/form-data body, and the live stream's
// messages. Pure functions on bytes (tests/fuzz/fuzz_serve.cpp feeds them arbitrary input):
// every malformed input is Error(kUsage) with a message naming the part and the problem, never
// a crash; nothing here touches the file system.
//
//   Target t = ParseTarget("/api/analyze?height=0.2&material=steel");
//   Query q(t.query);  q.TakeDouble("height");  q.Finish("/api/analyze");
//   UploadPart p = FindUpload(body, "multipart/form-data; boundary=xyz");
#pragma once

#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bouncecal::serve {

// A request target "/path?query": the path must start with '/' and be at most 2048 bytes of
// printable ASCII (no "..", no "//", no '\\', no percent-escapes in the path: routes are fixed
// names, so nothing else can be one).
struct Target {
  std::string path;
  std::vector<std::pair<std::string, std::string>> query;  // decoded, in order
};
Target ParseTarget(std::string_view target);

// "a=1&b=x%20y&flag" -> {{"a","1"},{"b","x y"},{"flag",""}}: percent-escapes and '+' decoded;
// keys normalised to snake_case ('-' -> '_'). At most 200 pairs, each key at most 64 bytes.
std::vector<std::pair<std::string, std::string>> ParseQuery(std::string_view query);

// The query's values by name. Each Take* reads and removes one (a repeated key: TakeAll);
// Finish refuses names nobody read (a misspelled parameter is an error, not ignored).
class Query {
 public:
  explicit Query(std::vector<std::pair<std::string, std::string>> pairs);
  bool Has(const std::string& name) const;
  std::optional<std::string> TakeString(const std::string& name);
  std::vector<std::string> TakeAll(const std::string& name);
  // A finite number (the whole value: "0.2", "1e-3"), else Error(kUsage) naming the key.
  std::optional<double> TakeDouble(const std::string& name);
  std::optional<int> TakeInt(const std::string& name);
  // "", "1", "true", "yes", "on" -> true; "0", "false", "no", "off" -> false; absent -> false.
  bool TakeFlag(const std::string& name);
  void Finish(const std::string& route) const;

 private:
  std::vector<std::pair<std::string, std::string>> pairs_;
};

// The file part of a multipart/form-data body: the first part with a filename (or, failing
// that, the first part). offset/size locate its content in `body`. Error(kUsage) for a content
// type without a boundary, a truncated body (no closing delimiter), or a part without headers.
struct UploadPart {
  std::size_t offset = 0;
  std::size_t size = 0;
  std::string filename;  // as sent ("" if none); a display name only, never a path
};
bool IsMultipart(std::string_view content_type);
UploadPart FindUpload(std::string_view body, std::string_view content_type);

// A display name for an upload: its last path component, printable characters only, at most
// 100 bytes; "upload" when nothing is left.
std::string DisplayName(std::string_view name);

// The first text message of a live stream: {"rate": R} (R a whole number of hertz in
// [8000, 384000]). Error(kUsage) naming what is wrong.
double ParseLiveStart(std::string_view text);
// A later text message: {"stop": true} is the only one. Returns true for it, else Error(kUsage).
bool ParseLiveControl(std::string_view text);
// A binary frame: mono little-endian float32 samples, a whole number of them, at most
// max_bytes. Error(kUsage) otherwise.
std::vector<float> ParseLiveSamples(std::string_view bytes, std::size_t max_bytes);

// A take's id in a URL: 32 lowercase hex digits.
bool IsSessionId(std::string_view id);

}  // namespace bouncecal::serve
