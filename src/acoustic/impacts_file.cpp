// Impact times from a file. See include/bouncecal/acoustic/impacts_file.hpp.
#include "bouncecal/acoustic/impacts_file.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"

namespace bouncecal {
namespace {

// One time as read, with where it came from (for messages).
struct RawTime {
  double t = 0.0;
  std::optional<double> sigma;
  int sequence = 0;
  int line = 0;  // 1-based line (CSV/labels/list) or 0-based impact index (JSON: see `where`)
  std::string where;
};

[[noreturn]] void Bad(const std::string& path, const std::string& where, const std::string& why) {
  throw Error(ErrorCode::kBadScene, path + (where.empty() ? "" : ":" + where) + ": " + why);
}

std::string Trim(std::string s) {
  const auto b = s.find_first_not_of(" \t\r\n\"");
  const auto e = s.find_last_not_of(" \t\r\n\"");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// Whole-field number (no trailing garbage), or nullopt.
std::optional<double> Number(const std::string& field) {
  const std::string s = Trim(field);
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || errno == ERANGE) return std::nullopt;
  return v;
}

std::vector<std::string> Split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    if (c == sep && !quoted) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

// The versions of `detect --json` read here: bouncecal.detect/2 lists each impact once, in its
// sequence; bouncecal.detect/1 also listed the first chosen sequence's impacts at the top level.
// A file without "schema" (written before it existed) is read as its sequences say.
void CheckDetectVersion(const std::string& path, const nlohmann::json& d) {
  if (!d.contains("schema")) return;
  if (!d["schema"].is_string()) Bad(path, "schema", "not a string");
  const std::string v = d["schema"].get<std::string>();
  if (v != "bouncecal.detect/1" && v != "bouncecal.detect/2")
    Bad(path, "schema",
        "'" + v + "' is not a detection this bouncecal reads (bouncecal.detect/2, or /1)");
}

// A top-level "impacts" list (bouncecal.detect/1, or one added by hand) is a second copy of the
// first chosen sequence's impacts. The times come from "sequences"; a copy that disagrees with
// them means the file was edited in the place that is not read: refused, naming both.
void CheckSecondCopy(const std::string& path, const nlohmann::json& d) {
  if (!d.contains("impacts")) return;
  const nlohmann::json& top = d["impacts"];
  if (!top.is_array()) Bad(path, "impacts", "not an array");
  const nlohmann::json& seqs = d["sequences"];
  std::size_t chosen = 0;
  for (const char* key : {"main_sequence", "chosen_sequences"}) {
    const nlohmann::json* c = d.contains(key) ? &d[key] : nullptr;
    if (c && c->is_array()) c = c->empty() ? nullptr : &(*c)[0];
    if (c && c->is_number_unsigned() && c->get<std::size_t>() < seqs.size())
      chosen = c->get<std::size_t>();
  }
  const std::string where = "sequences[" + std::to_string(chosen) + "].impacts";
  const nlohmann::json empty = nlohmann::json::array();
  const nlohmann::json& read =
      seqs.empty() || !seqs[chosen].contains("impacts") ? empty : seqs[chosen]["impacts"];
  const std::string advice =
      ": the two copies of bouncecal.detect/1 disagree, and --impacts reads " + where +
      ". Make the edit there (and delete \"impacts\"), or run detect again: bouncecal.detect/2 "
      "lists each impact once";
  auto time = [](const nlohmann::json& i) {
    return i.is_object() && i.contains("time_s") && i["time_s"].is_number()
               ? FormatFixed(i["time_s"].get<double>(), 6) + " s"
               : std::string("no time");
  };
  for (std::size_t k = 0; k < std::max(top.size(), read.size()); ++k) {
    const bool same = k < top.size() && k < read.size() && top[k].contains("time_s") &&
                      read[k].is_object() && read[k].contains("time_s") &&
                      top[k]["time_s"] == read[k]["time_s"];
    if (same) continue;
    Bad(path, "impacts[" + std::to_string(k) + "]",
        (k < top.size() ? time(top[k]) : "absent") + " where " + where + "[" + std::to_string(k) +
            "] has " + (k < read.size() ? time(read[k]) : "none") + advice);
  }
}

std::vector<RawTime> FromDetectJson(const std::string& path, const nlohmann::json& doc) {
  const nlohmann::json* d = &doc;
  if (doc.is_array()) {
    if (doc.size() != 1)
      Bad(path, "",
          "holds " + std::to_string(doc.size()) +
              " recordings' detections; give one recording's object");
    d = &doc[0];
  }
  if (!d->is_object() || !d->contains("sequences") || !(*d)["sequences"].is_array())
    Bad(path, "",
        "JSON without a \"sequences\" array: not a detection (schema bouncecal.detect/2)");
  CheckDetectVersion(path, *d);
  CheckSecondCopy(path, *d);
  std::vector<RawTime> out;
  int s = 0;
  for (const auto& q : (*d)["sequences"]) {
    if (!q.is_object() || !q.contains("impacts") || !q["impacts"].is_array())
      Bad(path, "sequences[" + std::to_string(s) + "]", "no \"impacts\" array");
    int k = 0;
    for (const auto& i : q["impacts"]) {
      const std::string where =
          "sequences[" + std::to_string(s) + "].impacts[" + std::to_string(k) + "]";
      if (!i.is_object() || !i.contains("time_s") || !i["time_s"].is_number())
        Bad(path, where, "time_s is missing or not a number");
      RawTime r;
      r.t = i["time_s"].get<double>();
      // time_sigma_s (bouncecal.detect/1 and /2; wins), sigma_s in files written before it.
      for (const char* key : {"sigma_s", "time_sigma_s"})
        if (i.contains(key) && i[key].is_number()) r.sigma = i[key].get<double>();
      r.sequence = s;
      r.where = where;
      out.push_back(r);
      ++k;
    }
    ++s;
  }
  return out;
}

// CSV with a header naming the time column; Audacity labels; or a plain list.
std::vector<RawTime> FromText(const std::string& path, const std::string& text,
                              std::string* format) {
  std::vector<std::string> lines;
  {
    std::istringstream in(text);
    std::string l;
    while (std::getline(in, l)) lines.push_back(l);
  }
  std::size_t first = 0;
  while (first < lines.size() && (Trim(lines[first]).empty() || Trim(lines[first])[0] == '#'))
    ++first;
  if (first == lines.size()) Bad(path, "", "no impact times in the file");
  const std::string head = lines[first];
  const char sep = head.find('\t') != std::string::npos  ? '\t'
                   : head.find(';') != std::string::npos ? ';'
                                                         : ',';
  const std::vector<std::string> cols = Split(head, sep);
  int t_col = -1, s_col = -1, q_col = -1;
  bool header = false;
  if (!Number(cols[0])) {
    header = true;
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const std::string n = Lower(Trim(cols[c]));
      if (t_col < 0 && (n == "time_s" || n == "t_impact_s" || n == "t_s" || n == "time" ||
                        n == "time (s)" || n == "t (s)" || n == "onset_s"))
        t_col = static_cast<int>(c);
      if (n == "time_sigma_s" || n == "sigma_s") s_col = static_cast<int>(c);
      if (n == "sequence") q_col = static_cast<int>(c);
    }
    if (t_col < 0)
      Bad(path, "1",
          "no time column in the header '" + Trim(head) +
              "' (expected time_s, t_impact_s, t_s, time or \"Time (s)\")");
    *format = "csv";
  } else {
    t_col = 0;
    *format = sep == '\t' && cols.size() >= 2 ? "audacity-labels" : "list";
  }
  std::vector<RawTime> out;
  for (std::size_t i = first + (header ? 1 : 0); i < lines.size(); ++i) {
    const std::string l = Trim(lines[i]);
    if (l.empty() || l[0] == '#') continue;
    const std::vector<std::string> f = Split(lines[i], sep);
    const std::string where = std::to_string(i + 1);
    if (static_cast<int>(f.size()) <= t_col)
      Bad(path, where, "no time in column " + std::to_string(t_col + 1));
    const std::optional<double> t = Number(f[static_cast<std::size_t>(t_col)]);
    if (!t) Bad(path, where, "'" + Trim(f[static_cast<std::size_t>(t_col)]) + "' is not a number");
    RawTime r;
    r.t = *t;
    r.line = static_cast<int>(i + 1);
    r.where = where;
    if (s_col >= 0 && static_cast<int>(f.size()) > s_col) {
      const std::string sf = Trim(f[static_cast<std::size_t>(s_col)]);
      if (!sf.empty()) {
        const std::optional<double> sg = Number(sf);
        if (!sg) Bad(path, where, "sigma_s '" + sf + "' is not a number");
        r.sigma = *sg;
      }
    }
    if (q_col >= 0 && static_cast<int>(f.size()) > q_col) {
      const std::optional<double> q = Number(f[static_cast<std::size_t>(q_col)]);
      if (!q || *q < 0 || *q != std::floor(*q) || *q > 1e6)
        Bad(path, where,
            "sequence '" + Trim(f[static_cast<std::size_t>(q_col)]) + "' is not a 0-based index");
      r.sequence = static_cast<int>(*q);
    }
    out.push_back(r);
  }
  return out;
}

// Checks every time and groups them into sequences.
std::vector<Sequence> Validate(const std::string& path, std::vector<RawTime> raw,
                               const ImpactsFileOptions& o) {
  if (raw.empty()) Bad(path, "", "no impact times in the file");
  std::vector<Sequence> seqs;
  std::vector<int> ids;
  for (const RawTime& r : raw) {
    if (!std::isfinite(r.t)) Bad(path, r.where, "time " + FormatGeneral(r.t) + " is not finite");
    if (r.t < 0.0) Bad(path, r.where, "time " + FormatGeneral(r.t) + " s is negative");
    if (o.duration_s && r.t > *o.duration_s)
      Bad(path, r.where,
          "time " + FormatFixed(r.t, 6) + " s is beyond the recording (" +
              FormatFixed(*o.duration_s, 6) + " s long)");
    if (r.sigma && (!std::isfinite(*r.sigma) || !(*r.sigma > 0.0)))
      Bad(path, r.where, "sigma_s " + FormatGeneral(*r.sigma) + " must be a finite number > 0");
    auto it = std::find(ids.begin(), ids.end(), r.sequence);
    if (it == ids.end()) {
      ids.push_back(r.sequence);
      seqs.emplace_back();
      seqs.back().end_reason = "from_file";
      it = ids.end() - 1;
    }
    Sequence& q = seqs[static_cast<std::size_t>(it - ids.begin())];
    if (!q.impacts.empty()) {
      const double prev = q.impacts.back().time_s;
      if (r.t == prev) Bad(path, r.where, "time " + FormatFixed(r.t, 6) + " s is a duplicate");
      if (r.t < prev)
        Bad(path, r.where,
            "time " + FormatFixed(r.t, 6) + " s comes after " + FormatFixed(prev, 6) +
                " s: times must be sorted");
    }
    Impact im;
    im.time_s = r.t;
    im.sigma_s = r.sigma.value_or(o.default_sigma_s);
    im.score = 1.0;
    q.impacts.push_back(im);
  }
  // Intervals of a bouncing ball shrink: one 1.5 times the previous or longer cannot be a single
  // flight (a deleted or missing impact). Flag it as the tracker flags a missed impact, so the
  // kinematics does not take it as one flight.
  for (Sequence& q : seqs)
    for (std::size_t k = 1; k + 1 < q.impacts.size(); ++k) {
      const double prev = q.impacts[k].time_s - q.impacts[k - 1].time_s;
      const double next = q.impacts[k + 1].time_s - q.impacts[k].time_s;
      if (next >= 1.5 * prev) q.missed_after.push_back(static_cast<int>(k));
    }
  for (std::size_t s = 0; s < seqs.size(); ++s)
    if (static_cast<int>(seqs[s].impacts.size()) < o.min_impacts)
      Bad(path, "",
          "sequence " + std::to_string(ids[s]) + " has " + std::to_string(seqs[s].impacts.size()) +
              " impact(s); a bounce sequence needs " + std::to_string(o.min_impacts));
  return seqs;
}

}  // namespace

bool ImpactsFileOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(default_sigma_s > 0.0) || !std::isfinite(default_sigma_s))
    return fail("ImpactsFileOptions::default_sigma_s = " + FormatGeneral(default_sigma_s) +
                ": must be a finite number > 0");
  if (duration_s && (!std::isfinite(*duration_s) || !(*duration_s > 0.0)))
    return fail("ImpactsFileOptions::duration_s = " + FormatGeneral(*duration_s) + ": must be > 0");
  if (min_impacts < 2)
    return fail("ImpactsFileOptions::min_impacts = " + std::to_string(min_impacts) +
                ": must be >= 2");
  return true;
}

ImpactsFile ReadImpactsFile(const std::string& path, const ImpactsFileOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  std::error_code ec;
  if (path.empty()) throw Error(ErrorCode::kInputMissing, "<empty path>: no impacts file given");
  if (!std::filesystem::exists(path, ec))
    throw Error(ErrorCode::kInputMissing, path + ": no such file");
  if (std::filesystem::is_directory(path, ec))
    throw Error(ErrorCode::kInputMissing, path + ": is a directory");
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw Error(ErrorCode::kInputMissing,
                path + ": cannot be opened for reading (" + std::strerror(errno) + ")");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  ImpactsFile f;
  f.path = path;
  const std::string t = Trim(text);
  std::vector<RawTime> raw;
  if (!t.empty() && (t[0] == '{' || t[0] == '[')) {
    nlohmann::json doc;
    try {
      doc = nlohmann::json::parse(text);
    } catch (const nlohmann::json::parse_error& e) {
      Bad(path, "byte " + std::to_string(e.byte), "not valid JSON");
    } catch (const nlohmann::json::exception&) {
      // A number beyond double's range ("1e542") is valid JSON syntax that nlohmann rejects as
      // out_of_range (found by tools/run-fuzz.sh: it escaped as an internal error).
      Bad(path, "", "JSON with a number beyond the range of a double");
    }
    raw = FromDetectJson(path, doc);
    f.format = "detect-json";
  } else {
    raw = FromText(path, text, &f.format);
  }
  f.sequences = Validate(path, std::move(raw), o);
  return f;
}

}  // namespace bouncecal
