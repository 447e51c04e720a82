// bouncecal/serve/live_session.hpp — one live stream of the server (WebSocket /api/live), apart
// from the network: the messages in, the messages out (io/live_json.hpp, docs/serve.md).
//
//   first   text {"rate": R}            -> started
//   then    binary float32 LE samples   -> impact / revised / warning (when something changed)
//   last    text {"stop": true}         -> the last impacts, then analysis; the session is done
// Anything else (a binary frame first, a frame of the wrong size or type, a NaN sample, a
// second start) throws Error naming the problem: the server sends it as an error message and
// closes this session only. The take is written as FLAC (PCM_24) as it arrives, in the
// server's takes directory (sessions.hpp), and analysed whole at the stop as `analyze TAKE`.
//
//   LiveSession s(&sessions, query, LiveSessionOptions{});
//   for (const nlohmann::json& m : s.OnText(R"({"rate": 48000})")) Send(m);
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/serve/sessions.hpp"

namespace bouncecal::serve {

struct LiveSessionOptions {
  LiveOptions live;
  // Largest binary message: 1 MiB is 5.5 s of audio at 48 kHz (a page sends ~0.05 s at a time).
  std::size_t max_frame_bytes = 1 << 20;
};

class LiveSession {
 public:
  // `query`: the WebSocket URL's parameters (the scene, as /api/analyze: height, diameter, ...;
  // and min_snr_db). Throws Error(kUsage/kBadParameter/kBadScene) before the stream starts.
  LiveSession(Sessions* sessions, std::vector<std::pair<std::string, std::string>> query,
              const LiveSessionOptions& options = {});
  ~LiveSession();  // a stream that did not stop: its session fails, its take is removed
  LiveSession(const LiveSession&) = delete;
  LiveSession& operator=(const LiveSession&) = delete;

  std::vector<nlohmann::json> OnText(std::string_view text);
  std::vector<nlohmann::json> OnBinary(std::string_view bytes);
  bool done() const { return state_ == State::kDone; }
  const std::string& id() const { return id_; }

 private:
  enum class State { kStart, kStreaming, kDone };
  struct Stream;
  std::vector<nlohmann::json> Stop();
  Sessions* sessions_;
  LiveSessionOptions options_;
  State state_ = State::kStart;
  std::string id_;
  std::unique_ptr<Stream> stream_;
};

}  // namespace bouncecal::serve
