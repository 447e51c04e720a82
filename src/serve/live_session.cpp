// One live stream of the server (include/bouncecal/serve/live_session.hpp).
#include "bouncecal/serve/live_session.hpp"

#include "bouncecal/acoustic/audio_writer.hpp"
#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/io/analysis_document.hpp"
#include "bouncecal/io/live_json.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/serve/query_options.hpp"
#include "bouncecal/serve/requests.hpp"

namespace bouncecal::serve {

struct LiveSession::Stream {
  GivenScene scene;
  AnalysisOptions analysis;
  DropInputOptions drops;  // the take's analysis: the main sequence, the stream's min_snr_db
  std::unique_ptr<LiveDetector> live;
  std::unique_ptr<AudioWriter> take;
  std::string take_path;
  std::string take_name;
};

LiveSession::LiveSession(Sessions* sessions, std::vector<std::pair<std::string, std::string>> query,
                         const LiveSessionOptions& options)
    : sessions_(sessions), options_(options), stream_(std::make_unique<Stream>()) {
  try {
    Query q(std::move(query));
    const SceneOverrides scene = TakeSceneQuery(q, /*with_law=*/false);
    const std::optional<double> contact_time_s = q.TakeDouble("contact_time");
    if (auto v = q.TakeDouble("min_snr_db")) options_.live.detect.min_snr_db = *v;
    q.Finish("/api/live");
    stream_->scene = ResolveGivenScene(scene);
    stream_->analysis = AnalyzeOptionsFor(&stream_->scene, contact_time_s);
    stream_->drops.detect.min_snr_db = options_.live.detect.min_snr_db;
    std::string why;
    if (!options_.live.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  } catch (const Error& e) {
    throw Error(e.code(), QueryText(e.what()));
  }
}

LiveSession::~LiveSession() {
  if (!id_.empty() && state_ != State::kDone) sessions_->Finish(id_, false);
}

std::vector<nlohmann::json> LiveSession::OnText(std::string_view text) {
  if (state_ == State::kDone) throw Error(ErrorCode::kUsage, "live: the stream has ended");
  if (state_ == State::kStreaming) {
    ParseLiveControl(text);
    return Stop();
  }
  const double rate = ParseLiveStart(text);
  id_ = sessions_->Create(rate);
  Stream& s = *stream_;
  s.take_path = sessions_->TakePath(id_);
  s.take_name = "take-" + id_ + ".flac";
  // PCM_24: a 16-bit source exactly, a float one to -144 dB (far below any microphone's noise).
  s.take =
      std::make_unique<AudioWriter>(s.take_path, rate, 1, AudioWriteOptions{.subtype = "PCM_24"});
  s.live = std::make_unique<LiveDetector>(rate, options_.live, "live session " + id_);
  state_ = State::kStreaming;
  return {LiveStartedJson(id_, rate, "/api/takes/" + id_ + ".flac")};
}

std::vector<nlohmann::json> LiveSession::OnBinary(std::string_view bytes) {
  if (state_ == State::kStart)
    throw Error(ErrorCode::kUsage, "live: the first message must be the text {\"rate\": R}");
  if (state_ == State::kDone) throw Error(ErrorCode::kUsage, "live: the stream has ended");
  Stream& s = *stream_;
  const std::vector<float> x = ParseLiveSamples(bytes, options_.max_frame_bytes);
  const LiveUpdate u = s.live->Feed(x);
  s.take->Write(x.data(), x.size());
  const bool changed = !u.impacts.empty() || !u.revisions.empty();
  const std::vector<LiveImpact> impacts = changed ? s.live->Impacts() : std::vector<LiveImpact>{};
  sessions_->Update(id_, s.live->frames(), changed ? &impacts : nullptr);
  return LiveUpdateJson(u, *s.live, {s.scene.scene, s.analysis});
}

std::vector<nlohmann::json> LiveSession::Stop() {
  Stream& s = *stream_;
  const LiveUpdate u = s.live->Finish();
  std::vector<nlohmann::json> out = LiveUpdateJson(u, *s.live, {s.scene.scene, s.analysis});
  const std::vector<LiveImpact> impacts = s.live->Impacts();
  sessions_->Update(id_, s.live->frames(), &impacts);
  const std::int64_t frames = s.take->frames();
  s.take->Commit();
  nlohmann::json analysis = nullptr, error = nullptr;
  try {
    const LoadedRecording l = LoadRecording(s.take_path, nullptr, "", s.drops);
    analysis = AnalysisDocuments(s.take_name, l, s.scene, s.analysis).front();
  } catch (const Error& e) {
    std::string message = e.what();
    for (std::size_t at; (at = message.find(s.take_path)) != std::string::npos;)
      message.replace(at, s.take_path.size(), s.take_name);
    error = ErrorJson(e.code(), message);
  }
  nlohmann::json take = nlohmann::json::object();
  take["id"] = id_;
  take["url"] = "/api/takes/" + id_ + ".flac";
  take["frames"] = frames;
  take["sample_rate_hz"] = s.live->rate_hz();
  take["duration_s"] = static_cast<double>(frames) / s.live->rate_hz();
  out.push_back(LiveAnalysisMessageJson(analysis, error, take));
  sessions_->Finish(id_, true);
  state_ = State::kDone;
  return out;
}

}  // namespace bouncecal::serve
