// bouncecal/core/user_text.hpp — user-supplied strings (paths, law names, expressions) inside
// our messages and JSON.
//
// A file name is bytes, not text: on Linux it need not be UTF-8, and JSON strings must be.
// Every JSON document the tool prints or writes goes through DumpJson, which keeps valid UTF-8
// as is and writes each byte that is not part of a valid UTF-8 sequence as the four characters
// "\xNN" (like Python's "backslashreplace"), so the name stays recognisable and the document
// stays valid. Human-readable output prints names as given (the bytes).
//
// Messages that echo a user string (a law name, an expression, a key) pass it through
// Abbreviate so a 2 MB argument does not become a 2 MB message.
//
//   std::cout << DumpJson(doc, 2) << "\n";
//   throw Error(ErrorCode::kBadParameter, "unknown law '" + Abbreviate(name) + "'");
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace bouncecal {

// `s` with every byte outside a valid UTF-8 sequence written as "\xNN" (two upper-case hex
// digits). Valid UTF-8 comes back unchanged.
std::string EscapeInvalidUtf8(std::string_view s);

// `j` as text (nlohmann's dump with `indent`, -1 = one line), with every string and key passed
// through EscapeInvalidUtf8 first when it is not valid UTF-8. Never throws for invalid UTF-8.
std::string DumpJson(const nlohmann::json& j, int indent = -1);

// Echo of a user string in a message: invalid UTF-8 escaped, at most `max_chars` characters
// (code points) kept, and "… (N bytes)" appended when it was cut.
inline constexpr std::size_t kEchoMaxChars = 80;
std::string Abbreviate(std::string_view s, std::size_t max_chars = kEchoMaxChars);

// A library name (an Options field, "SceneOverrides::height_m") and what a front end calls it
// (a flag "--height", a keyword "height").
struct NameInFrontEnd {
  const char* library;
  const char* front_end;
};
// `message` with each library name replaced by its front-end name, as a whole name only
// ("SceneOverrides::law" does not match inside "SceneOverrides::law_sets"), in table order.
std::string RenameFields(const std::string& message, std::span<const NameInFrontEnd> names);

}  // namespace bouncecal
