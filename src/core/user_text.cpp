#include "bouncecal/core/user_text.hpp"

#include <cstdio>
#include <cstdlib>

#include <cstdint>

namespace bouncecal {
namespace {

// Length of the valid UTF-8 sequence starting at s[i] (1-4), or 0 when the byte there does not
// start one. Rules: RFC 3629 section 4 (no overlong forms, no surrogates, at most U+10FFFF).
std::size_t Utf8SequenceLength(std::string_view s, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<std::uint8_t>(s[k]); };
  const std::uint8_t b0 = byte(i);
  if (b0 < 0x80) return 1;
  std::size_t n = 0;
  std::uint8_t lo = 0x80, hi = 0xBF;  // allowed range of the second byte
  if (b0 >= 0xC2 && b0 <= 0xDF) {
    n = 2;
  } else if (b0 >= 0xE0 && b0 <= 0xEF) {
    n = 3;
    if (b0 == 0xE0) lo = 0xA0;  // overlong
    if (b0 == 0xED) hi = 0x9F;  // surrogates
  } else if (b0 >= 0xF0 && b0 <= 0xF4) {
    n = 4;
    if (b0 == 0xF0) lo = 0x90;  // overlong
    if (b0 == 0xF4) hi = 0x8F;  // above U+10FFFF
  } else {
    return 0;
  }
  if (i + n > s.size()) return 0;
  if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
  for (std::size_t k = 2; k < n; ++k) {
    if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
  }
  return n;
}

bool IsValidUtf8(std::string_view s) {
  for (std::size_t i = 0; i < s.size();) {
    const std::size_t n = Utf8SequenceLength(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

// A copy of `j` with every string and key made valid UTF-8.
nlohmann::json Escaped(const nlohmann::json& j) {
  if (j.is_string()) return EscapeInvalidUtf8(j.get_ref<const std::string&>());
  if (j.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& v : j) out.push_back(Escaped(v));
    return out;
  }
  if (j.is_object()) {
    nlohmann::json out = nlohmann::json::object();
    for (auto it = j.begin(); it != j.end(); ++it) out[EscapeInvalidUtf8(it.key())] = Escaped(*it);
    return out;
  }
  return j;
}

}  // namespace

std::string EscapeInvalidUtf8(std::string_view s) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(s.size());
  for (std::size_t i = 0; i < s.size();) {
    const std::size_t n = Utf8SequenceLength(s, i);
    if (n > 0) {
      out.append(s.substr(i, n));
      i += n;
      continue;
    }
    const auto b = static_cast<std::uint8_t>(s[i++]);
    out += "\\x";
    out += kHex[b >> 4];
    out += kHex[b & 0xF];
  }
  return out;
}

std::string DumpJson(const nlohmann::json& j, int indent) {
  try {
    return j.dump(indent);
  } catch (const nlohmann::json::type_error&) {
    // Only invalid UTF-8 in a string makes dump() throw (error 316): escape and dump again.
    return Escaped(j).dump(indent);
  }
}

std::string Abbreviate(std::string_view s, std::size_t max_chars) {
  const std::string text = IsValidUtf8(s) ? std::string(s) : EscapeInvalidUtf8(s);
  std::size_t chars = 0, i = 0;
  while (i < text.size() && chars < max_chars) {
    i += Utf8SequenceLength(text, i);
    ++chars;
  }
  if (i >= text.size()) return text;
  return text.substr(0, i) + "… (" + std::to_string(s.size()) + " bytes)";
}

namespace {
bool NameChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
}
}  // namespace

std::string RenameFields(const std::string& message, std::span<const NameInFrontEnd> names) {
  std::string m = message;
  for (const NameInFrontEnd& f : names) {
    const std::string from = f.library, to = f.front_end;
    std::size_t at = m.find(from);
    while (at != std::string::npos) {
      const std::size_t end = at + from.size();
      if (end < m.size() && NameChar(m[end])) {
        at = m.find(from, end);
        continue;
      }
      m.replace(at, from.size(), to);
      at = m.find(from, at + to.size());
    }
  }
  return m;
}

}  // namespace bouncecal
