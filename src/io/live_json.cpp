// The messages of a live stream (include/bouncecal/io/live_json.hpp).
#include "bouncecal/io/live_json.hpp"

#include "bouncecal/io/schema.hpp"

namespace bouncecal {
namespace {

nlohmann::json Message(const char* type) {
  nlohmann::json m = nlohmann::json::object();
  m["schema"] = kLiveSchema;
  m["type"] = type;
  return m;
}

// The analysis of a live sequence's final members with the stream's scene (null rows when it has
// fewer than two, or the kinematics refuse them).
std::optional<Analysis> Rows(const LiveDetector& live, int sequence,
                             const LiveJsonOptions& options) {
  const Sequence q = live.FinalSequence(sequence);
  if (q.impacts.size() < 2) return std::nullopt;
  try {
    return AnalyzeBounces(q, options.scene, options.analysis);
  } catch (const Error&) {
    return std::nullopt;
  }
}

}  // namespace

nlohmann::json LiveImpactJson(const LiveImpact& impact) {
  nlohmann::json j = nlohmann::json::object();
  j["sequence"] = impact.sequence;
  j["index"] = impact.index;
  const nlohmann::json fields = ImpactJson(impact.impact);
  for (auto it = fields.begin(); it != fields.end(); ++it) j[it.key()] = *it;
  return j;
}

std::vector<nlohmann::json> LiveUpdateJson(const LiveUpdate& update, const LiveDetector& live,
                                           const LiveJsonOptions& options) {
  std::vector<nlohmann::json> out;
  for (const LiveRevision& r : update.revisions) {
    nlohmann::json m = Message("revised");
    m["sequence"] = r.sequence;
    m["reason"] = r.reason;
    m["impacts"] = nlohmann::json::array();
    for (std::size_t k = 0; k < r.impacts.size(); ++k)
      m["impacts"].push_back(LiveImpactJson({r.sequence, static_cast<int>(k), r.impacts[k]}));
    m["bounces"] = nlohmann::json::array();
    if (const auto rows = Rows(live, r.sequence, options))
      for (const Bounce& b : rows->bounces) m["bounces"].push_back(BounceJson(b));
    out.push_back(std::move(m));
  }
  for (const LiveImpact& i : update.impacts) {
    nlohmann::json m = Message("impact");
    m["impact"] = LiveImpactJson(i);
    m["bounce"] = nullptr;
    if (i.index > 0) {
      if (const auto rows = Rows(live, i.sequence, options)) {
        for (const Bounce& b : rows->bounces)
          if (b.index == i.index - 1) m["bounce"] = BounceJson(b);
      }
    }
    out.push_back(std::move(m));
  }
  for (const Warning& w : update.warnings) {
    nlohmann::json m = Message("warning");
    m["warning"] = WarningsJson({w})[0];
    out.push_back(std::move(m));
  }
  return out;
}

nlohmann::json LiveStartedJson(const std::string& session, double rate_hz,
                               const std::string& take_url) {
  nlohmann::json m = Message("started");
  m["session"] = session;
  m["rate"] = rate_hz;
  m["take_url"] = take_url;
  return m;
}

nlohmann::json LiveAnalysisMessageJson(const nlohmann::json& analysis, const nlohmann::json& error,
                                       const nlohmann::json& take) {
  nlohmann::json m = Message("analysis");
  m["analysis"] = analysis;
  m["error"] = error;
  m["take"] = take;
  return m;
}

nlohmann::json LiveErrorJson(ErrorCode code, const std::string& message) {
  nlohmann::json m = Message("error");
  m["error"] = ErrorJson(code, message);
  return m;
}

nlohmann::json LiveSessionJson(const std::string& id, const std::string& started_utc,
                               const std::string& state, double rate_hz, std::int64_t samples,
                               const std::vector<LiveImpact>& impacts) {
  nlohmann::json j = nlohmann::json::object();
  j["schema"] = kLiveSessionSchema;
  j["id"] = id;
  j["started"] = started_utc;
  j["state"] = state;
  j["rate"] = rate_hz;
  j["samples"] = samples;
  j["impacts"] = nlohmann::json::array();
  for (const LiveImpact& i : impacts) j["impacts"].push_back(LiveImpactJson(i));
  return j;
}

}  // namespace bouncecal
