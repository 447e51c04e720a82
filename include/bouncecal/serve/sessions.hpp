// bouncecal/serve/sessions.hpp — the live sessions of one server and their takes: what
// GET /api/sessions lists and GET /api/takes/ID.flac serves. Thread-safe.
//
// A session is live while its WebSocket streams, then finished (its take kept as FLAC in the
// server's own directory) or failed (no take). The last `keep_finished` finished or failed
// sessions are kept; an older one is forgotten and its take deleted, so a server that runs for
// days holds a bounded number of takes. Ids are 128-bit random (IsSessionId): a take's URL is
// known only to whoever streamed it (and to GET /api/sessions on the same server).
//
//   Sessions s("/tmp/bouncecal-serve-x/takes");
//   const std::string id = s.Create(48000.0);
//   const auto impacts = live.Impacts();
//   s.Update(id, frames, &impacts);
//   s.Finish(id, true);   // the take at s.TakePath(id) is complete
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/live.hpp"

namespace bouncecal::serve {

class Sessions {
 public:
  Sessions(std::string takes_dir, int keep_finished = 16);
  ~Sessions();
  Sessions(const Sessions&) = delete;
  Sessions& operator=(const Sessions&) = delete;

  // A new live session; returns its id.
  std::string Create(double rate_hz);
  // Where a session's take is written (takes_dir/ID.flac); the session writes it itself.
  std::string TakePath(const std::string& id) const;
  // The samples received so far, and the final impacts when they changed (null: unchanged).
  void Update(const std::string& id, std::int64_t samples, const std::vector<LiveImpact>* impacts);
  // The stream ended: with its take (ok) or without (failed, the take removed).
  void Finish(const std::string& id, bool ok);
  // [bouncecal.live_session/1], oldest first.
  nlohmann::json List() const;
  // The finished take of a session, if there is one.
  std::optional<std::string> FinishedTake(const std::string& id) const;

 private:
  struct Entry;
  void Forget();  // beyond keep_finished: the oldest ended sessions and their takes
  std::string dir_;
  int keep_;
  mutable std::mutex mu_;
  std::deque<Entry> entries_;
};

// 32 random lowercase hex digits.
std::string NewSessionId();

}  // namespace bouncecal::serve
