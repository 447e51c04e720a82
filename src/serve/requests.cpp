// What the server reads from a request (include/bouncecal/serve/requests.hpp).
#include "bouncecal/serve/requests.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"

namespace bouncecal::serve {
namespace {

constexpr std::size_t kMaxTarget = 2048;
constexpr std::size_t kMaxPairs = 200;
constexpr std::size_t kMaxKey = 64;
constexpr std::size_t kMaxControlMessage = 4096;

[[noreturn]] void Fail(const std::string& message) { throw Error(ErrorCode::kUsage, message); }

// A value as it may appear in a message: cut, and non-UTF-8 bytes escaped.
std::string Shown(std::string_view v) {
  std::string out(1, '\'');
  out += Abbreviate(v);
  out += '\'';
  return out;
}

int HexDigit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string Decode(std::string_view s, const char* what) {
  std::string out;
  out.reserve(s.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '+') {
      out += ' ';
    } else if (s[i] == '%') {
      const int hi = i + 1 < s.size() ? HexDigit(s[i + 1]) : -1;
      const int lo = i + 2 < s.size() ? HexDigit(s[i + 2]) : -1;
      if (hi < 0 || lo < 0)
        Fail(std::string("query ") + what + ": a '%' not followed by two hex digits");
      out += static_cast<char>(hi * 16 + lo);
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

// The value of parameter `name` in a header value ("multipart/form-data; boundary=x").
std::string HeaderParameter(std::string_view value, std::string_view name) {
  std::size_t at = 0;
  while ((at = value.find(';', at)) != std::string_view::npos) {
    ++at;
    while (at < value.size() && (value[at] == ' ' || value[at] == '\t')) ++at;
    if (Lower(value.substr(at, name.size())) != name || at + name.size() >= value.size() ||
        value[at + name.size()] != '=')
      continue;
    std::size_t begin = at + name.size() + 1;
    if (begin < value.size() && value[begin] == '"') {
      const std::size_t end = value.find('"', begin + 1);
      if (end == std::string_view::npos) return "";
      return std::string(value.substr(begin + 1, end - begin - 1));
    }
    std::size_t end = begin;
    while (end < value.size() && value[end] != ';' && value[end] != ' ' && value[end] != '\t')
      ++end;
    return std::string(value.substr(begin, end - begin));
  }
  return "";
}

}  // namespace

Target ParseTarget(std::string_view target) {
  if (target.size() > kMaxTarget)
    Fail("request target of " + std::to_string(target.size()) + " bytes (at most " +
         std::to_string(kMaxTarget) + ")");
  if (target.empty() || target.front() != '/') Fail("request target must start with '/'");
  for (char c : target)
    if (static_cast<unsigned char>(c) < 0x21 || static_cast<unsigned char>(c) > 0x7e)
      Fail("request target with a byte that is not printable ASCII");
  Target t;
  const std::size_t q = target.find('?');
  t.path = std::string(target.substr(0, q));
  if (t.path.find("..") != std::string::npos || t.path.find("//") != std::string::npos ||
      t.path.find('\\') != std::string::npos || t.path.find('%') != std::string::npos)
    Fail("request path " + Shown(t.path) + ": no route has '..', '//', '\\' or '%' in it");
  if (q != std::string_view::npos) t.query = ParseQuery(target.substr(q + 1));
  return t;
}

std::vector<std::pair<std::string, std::string>> ParseQuery(std::string_view query) {
  std::vector<std::pair<std::string, std::string>> out;
  std::size_t at = 0;
  while (at <= query.size() && !query.empty()) {
    std::size_t end = query.find('&', at);
    if (end == std::string_view::npos) end = query.size();
    const std::string_view item = query.substr(at, end - at);
    at = end + 1;
    if (item.empty()) {
      if (end == query.size()) break;
      continue;
    }
    if (out.size() == kMaxPairs)
      Fail("query with more than " + std::to_string(kMaxPairs) + " parameters");
    const std::size_t eq = item.find('=');
    std::string key = Decode(item.substr(0, eq), "key");
    std::string value = eq == std::string_view::npos ? "" : Decode(item.substr(eq + 1), "value");
    if (key.empty()) Fail("query parameter without a name");
    if (key.size() > kMaxKey) Fail("query parameter name " + Shown(key) + " is too long");
    std::replace(key.begin(), key.end(), '-', '_');
    out.emplace_back(std::move(key), std::move(value));
    if (end == query.size()) break;
  }
  return out;
}

Query::Query(std::vector<std::pair<std::string, std::string>> pairs) : pairs_(std::move(pairs)) {}

bool Query::Has(const std::string& name) const {
  return std::any_of(pairs_.begin(), pairs_.end(), [&](const auto& p) { return p.first == name; });
}

std::vector<std::string> Query::TakeAll(const std::string& name) {
  std::vector<std::string> out;
  for (const auto& p : pairs_)
    if (p.first == name) out.push_back(p.second);
  std::erase_if(pairs_, [&](const auto& p) { return p.first == name; });
  return out;
}

std::optional<std::string> Query::TakeString(const std::string& name) {
  std::vector<std::string> all = TakeAll(name);
  if (all.empty()) return std::nullopt;
  if (all.size() > 1) Fail("parameter " + name + " given " + std::to_string(all.size()) + " times");
  return all.front();
}

std::optional<double> Query::TakeDouble(const std::string& name) {
  const auto s = TakeString(name);
  if (!s) return std::nullopt;
  double v = 0.0;
  const char* end = s->data() + s->size();
  const auto r = std::from_chars(s->data(), end, v);
  if (s->empty() || r.ec != std::errc() || r.ptr != end || !std::isfinite(v))
    Fail("parameter " + name + "=" + Shown(*s) + ": expected a finite number");
  return v;
}

std::optional<int> Query::TakeInt(const std::string& name) {
  const auto s = TakeString(name);
  if (!s) return std::nullopt;
  int v = 0;
  const char* end = s->data() + s->size();
  const auto r = std::from_chars(s->data(), end, v);
  if (s->empty() || r.ec != std::errc() || r.ptr != end)
    Fail("parameter " + name + "=" + Shown(*s) + ": expected a whole number");
  return v;
}

bool Query::TakeFlag(const std::string& name) {
  const auto s = TakeString(name);
  if (!s) return false;
  const std::string v = Lower(*s);
  if (v.empty() || v == "1" || v == "true" || v == "yes" || v == "on") return true;
  if (v == "0" || v == "false" || v == "no" || v == "off") return false;
  Fail("parameter " + name + "=" + Shown(*s) + ": expected true or false");
}

void Query::Finish(const std::string& route) const {
  if (pairs_.empty()) return;
  std::string names;
  for (const auto& p : pairs_)
    if (names.find(p.first) == std::string::npos) names += (names.empty() ? "" : ", ") + p.first;
  Fail(route + ": unknown parameter(s) " + Shown(names) + " (docs/serve.md lists them)");
}

bool IsMultipart(std::string_view content_type) {
  return Lower(content_type.substr(0, std::min<std::size_t>(content_type.size(), 19))) ==
         "multipart/form-data";
}

UploadPart FindUpload(std::string_view body, std::string_view content_type) {
  const std::string boundary = HeaderParameter(content_type, "boundary");
  if (boundary.empty() || boundary.size() > 200)
    Fail("multipart/form-data without a usable boundary parameter");
  const std::string delimiter = "--" + boundary;
  std::size_t at = body.find(delimiter);
  if (at == std::string_view::npos)
    Fail("multipart body without its boundary: truncated or not multipart");
  std::optional<UploadPart> first;
  for (int parts = 0; parts < 100; ++parts) {
    at += delimiter.size();
    if (body.substr(at, 2) == "--") break;  // the closing delimiter
    if (body.substr(at, 2) != "\r\n") Fail("multipart body: a boundary not followed by CRLF");
    const std::size_t headers = at + 2;
    const std::size_t blank = body.find("\r\n\r\n", headers);
    if (blank == std::string_view::npos)
      Fail("multipart body: a part without the end of its headers (truncated)");
    const std::string_view head = body.substr(headers, blank - headers);
    const std::size_t content = blank + 4;
    const std::size_t next = body.find("\r\n" + delimiter, content);
    if (next == std::string_view::npos) Fail("multipart body: truncated (no closing boundary)");
    UploadPart part;
    part.offset = content;
    part.size = next - content;
    for (std::size_t line = 0; line < head.size();) {
      std::size_t eol = head.find("\r\n", line);
      if (eol == std::string_view::npos) eol = head.size();
      const std::string_view h = head.substr(line, eol - line);
      if (Lower(h.substr(0, 20)) == "content-disposition:")
        part.filename = HeaderParameter(h, "filename");
      line = eol + 2;
    }
    if (!part.filename.empty()) return part;
    if (!first) first = part;
    at = next + 2;
  }
  if (!first) Fail("multipart body without a part");
  return *first;
}

std::string DisplayName(std::string_view name) {
  const std::size_t slash = name.find_last_of("/\\");
  if (slash != std::string_view::npos) name = name.substr(slash + 1);
  std::string out;
  for (char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u != 0x7f && out.size() < 100) out += c;
  }
  if (out.empty() || out == "." || out == "..") return "upload";
  return out;
}

double ParseLiveStart(std::string_view text) {
  if (text.size() > kMaxControlMessage) Fail("live: the start message is too long");
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    Fail("live: the first message must be the JSON object {\"rate\": R}");
  for (auto it = j.begin(); it != j.end(); ++it)
    if (it.key() != "rate") Fail("live: unknown key " + Shown(it.key()) + " in the start message");
  if (!j.contains("rate") || !j["rate"].is_number())
    Fail("live: the start message needs \"rate\": the sample rate in Hz");
  const double rate = j["rate"].get<double>();
  if (!(rate >= kMinSampleRateHz && rate <= kMaxSampleRateHz) || rate != std::round(rate))
    Fail("live: rate " + Shown(j["rate"].dump()) + ": expected a whole number of Hz in [" +
         std::to_string(kMinSampleRateHz) + ", " + std::to_string(kMaxSampleRateHz) + "]");
  return rate;
}

bool ParseLiveControl(std::string_view text) {
  if (text.size() > kMaxControlMessage) Fail("live: a text message is too long");
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.size() != 1 || !j.contains("stop") ||
      j["stop"] != true)
    Fail("live: the only text message after the start is {\"stop\": true}");
  return true;
}

std::vector<float> ParseLiveSamples(std::string_view bytes, std::size_t max_bytes) {
  if (bytes.size() > max_bytes)
    Fail("live: a binary message of " + std::to_string(bytes.size()) + " bytes (at most " +
         std::to_string(max_bytes) + ")");
  if (bytes.size() % 4 != 0)
    Fail("live: a binary message of " + std::to_string(bytes.size()) +
         " bytes is not a whole number of float32 samples");
  std::vector<float> out(bytes.size() / 4);
  static_assert(std::endian::native == std::endian::little, "samples are little-endian");
  if (!out.empty()) std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

bool IsSessionId(std::string_view id) {
  return id.size() == 32 && std::all_of(id.begin(), id.end(), [](char c) {
           return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
         });
}

}  // namespace bouncecal::serve
