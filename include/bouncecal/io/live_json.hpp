// bouncecal/io/live_json.hpp — the messages of a live stream (bouncecal.live/1, docs/serve.md):
// what the server's WebSocket /api/live sends, what `bouncecal listen --json` prints one per
// line, and what Python's Listener returns. Each is an object {"schema": "bouncecal.live/1",
// "type": ..., ...}:
//   started   {"session", "rate", "take_url"}                        the stream was accepted
//   impact    {"impact": live impact, "bounce": bounce | null}       an impact became final;
//             "bounce" is the previous impact's row of the analysis, now that this impact
//             closed its rebound flight (its e, v_in, v_out with sigmas; null for a sequence's
//             first impact)
//   revised   {"sequence", "reason", "impacts": [live impact], "bounces": [bounce]}
//             a sequence's final members changed: these replace every earlier one of it
//   warning   {"warning": {"code", "message", "impact"}}
//   analysis  {"analysis": bouncecal.analysis/1 | null, "error": error | null, "take": {...}}
//             the whole take's analysis (what `analyze TAKE --json` prints) at the end
//   error     {"error": {"code", "exit_code", "message"}}               the stream was refused
// A live impact is {"sequence", "index", "time_s", "time_sigma_s", "amplitude", "snr_db",
// "score", "clipped"}; bounce rows are schema.hpp's BounceJson, from AnalyzeBounces of the
// sequence's final members with the stream's scene.
//
//   for (const nlohmann::json& m : LiveUpdateJson(live.Feed(x), live, {gs.scene, options})) ...
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

inline constexpr const char* kLiveSchema = "bouncecal.live/1";
inline constexpr const char* kLiveSessionSchema = "bouncecal.live_session/1";

// {"sequence", "index", "time_s", "time_sigma_s", "amplitude", "snr_db", "score", "clipped"}
nlohmann::json LiveImpactJson(const LiveImpact& impact);

// What the bounce rows are computed with.
struct LiveJsonOptions {
  Scene scene;
  AnalysisOptions analysis;
};
// The messages of one update, in order: revised, impact, warning.
std::vector<nlohmann::json> LiveUpdateJson(const LiveUpdate& update, const LiveDetector& live,
                                           const LiveJsonOptions& options);

nlohmann::json LiveStartedJson(const std::string& session, double rate_hz,
                               const std::string& take_url);
// take: {"id", "url", "frames", "duration_s", "sample_rate_hz"} (or null when none was kept).
nlohmann::json LiveAnalysisMessageJson(const nlohmann::json& analysis, const nlohmann::json& error,
                                       const nlohmann::json& take);
nlohmann::json LiveErrorJson(ErrorCode code, const std::string& message);

// bouncecal.live_session/1: {"schema", "id", "started" (ISO 8601 UTC), "state" ("live" |
// "finished" | "failed"), "rate", "samples", "impacts": [live impact]} (GET /api/sessions).
nlohmann::json LiveSessionJson(const std::string& id, const std::string& started_utc,
                               const std::string& state, double rate_hz, std::int64_t samples,
                               const std::vector<LiveImpact>& impacts);

}  // namespace bouncecal
