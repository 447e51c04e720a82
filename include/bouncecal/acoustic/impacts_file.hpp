// bouncecal/acoustic/impacts_file.hpp — impact times from a file instead of from detection.
//
// A user who sees a wrong impact deletes or adds it by hand, or brings times from another tool.
// Formats (recognised from the content, not the extension):
//   - `bouncecal detect --json` output (one recording's object, or an array holding one): every
//     sequence with its impacts' time_s and time_sigma_s. bouncecal.detect/2 lists each impact
//     once, in its sequence: delete or add it there. bouncecal.detect/1 also listed the first
//     chosen sequence's impacts at the top level ("impacts"); such a copy must agree with the
//     sequence it copies, else the file is refused (an edit made where it is not read);
//   - CSV with a header: a time column named time_s, t_impact_s, t_s, time or "Time (s)"
//     (phyphox), optional sigma_s and sequence columns (`detect --csv` output, the shared
//     annotation files); `,` or `;` or tab separated;
//   - Audacity labels: tab-separated `start<TAB>end<TAB>label` lines, no header (start is used);
//   - one time per line (aubio's `aubioonset` output), `#` comments allowed.
// Times are seconds from the start of the recording, strictly increasing within a sequence,
// >= 0 and, when the recording's duration is known, not beyond it. Times without a sigma get
// ImpactsFileOptions::default_sigma_s. An interval 1.5 times the previous one or longer (an
// impact deleted by hand) is flagged in Sequence::missed_after, as the tracker flags a gap.
//
//   ImpactsFile f = ReadImpactsFile("fixed.json", ImpactsFileOptions{.duration_s = 12.8});
//
// Errors: Error(kInputMissing) for a missing/unreadable file; Error(kBadScene, exit 8: a malformed
// input file) naming the file and line for anything else (no time column, non-numeric, negative,
// unsorted or duplicate times, times beyond the recording, fewer than min_impacts in a sequence,
// a detect JSON of an unknown schema version or whose two copies of the impacts disagree).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {

struct ImpactsFileOptions {
  // Sigma of a time given without one: hand-placed and other tools' times are good to about
  // 0.2 ms (the shared recordings' confident annotations); give sigma_s to say otherwise.
  double default_sigma_s = 2e-4;
  std::optional<double> duration_s;  // the recording's length: later times are an error
  int min_impacts = 3;               // a sequence needs at least this many (a ratio needs 3)
  bool IsValid(std::string* error) const;
};

struct ImpactsFile {
  std::string path;
  std::string format;               // "detect-json", "csv", "audacity-labels", "list"
  std::vector<Sequence> sequences;  // in file order; end_reason "from_file"
};

ImpactsFile ReadImpactsFile(const std::string& path, const ImpactsFileOptions& options = {});

}  // namespace bouncecal
