// bouncecal/core/warning.hpp — a coded diagnostic: what a result's user must know about it.
//
// A result is either trustworthy or flagged. Every stage that can produce a number that looks
// precise but is not (a phantom impact, a drop height that cannot be right, a fit at a bound)
// adds a Warning with a stable machine-readable `code` (snake_case; listed in docs/cli.md), a
// one-line human `message` naming the values involved, the impact (or bounce) it concerns, and
// a `hint`: the next step, naming the flag, scene value or law to try (command-line names; the
// scene key beside a flag where a scene file can say it too).
//
//   out.warnings.push_back({"e_above_one", "impact 3: e = 1.02 +- 0.004 > 1", 3,
//                           "check the drop height (--height) and the impact list"});
//
// JSON form (every command): {"code": "...", "message": "...", "impact": 3 | null, "hint": "..."}.
#pragma once

#include <string>
#include <vector>

namespace bouncecal {

struct Warning {
  std::string code;     // stable, snake_case: scripts test it
  std::string message;  // one line, for people
  int impact = -1;      // index of the impact/bounce concerned (in its sequence), -1 = none
  std::string hint;     // what to try next, one line (flags, scene values, laws)
};

// True if `warnings` holds one with this code.
inline bool HasWarning(const std::vector<Warning>& warnings, const std::string& code) {
  for (const Warning& w : warnings)
    if (w.code == code) return true;
  return false;
}

}  // namespace bouncecal
