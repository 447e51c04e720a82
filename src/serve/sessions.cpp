// The live sessions of one server (include/bouncecal/serve/sessions.hpp).
#include "bouncecal/serve/sessions.hpp"

#include <filesystem>
#include <random>

#include "bouncecal/io/live_json.hpp"
#include "bouncecal/io/provenance.hpp"

namespace bouncecal::serve {

struct Sessions::Entry {
  std::string id;
  std::string started;
  std::string state = "live";
  double rate_hz = 0.0;
  std::int64_t samples = 0;
  std::vector<LiveImpact> impacts;
};

std::string NewSessionId() {
  static std::mutex mu;
  static std::random_device device;
  std::lock_guard<std::mutex> lock(mu);
  static constexpr char kHex[] = "0123456789abcdef";
  std::string id;
  for (int i = 0; i < 4; ++i) {
    std::uint32_t v = device();
    for (int k = 0; k < 8; ++k, v >>= 4) id += kHex[v & 15u];
  }
  return id;
}

Sessions::Sessions(std::string takes_dir, int keep_finished)
    : dir_(std::move(takes_dir)), keep_(keep_finished) {
  std::filesystem::create_directories(dir_);
}

Sessions::~Sessions() = default;

std::string Sessions::Create(double rate_hz) {
  Entry e;
  e.id = NewSessionId();
  e.started = NowIsoDateUtc();
  e.rate_hz = rate_hz;
  std::lock_guard<std::mutex> lock(mu_);
  entries_.push_back(e);
  return e.id;
}

std::string Sessions::TakePath(const std::string& id) const {
  return (std::filesystem::path(dir_) / (id + ".flac")).string();
}

void Sessions::Update(const std::string& id, std::int64_t samples,
                      const std::vector<LiveImpact>* impacts) {
  std::lock_guard<std::mutex> lock(mu_);
  for (Entry& e : entries_)
    if (e.id == id) {
      e.samples = samples;
      if (impacts != nullptr) e.impacts = *impacts;
    }
}

void Sessions::Finish(const std::string& id, bool ok) {
  std::lock_guard<std::mutex> lock(mu_);
  for (Entry& e : entries_)
    if (e.id == id) e.state = ok ? "finished" : "failed";
  if (!ok) {
    std::error_code ec;
    std::filesystem::remove(TakePath(id), ec);
  }
  Forget();
}

void Sessions::Forget() {
  int ended = 0;
  for (const Entry& e : entries_) ended += e.state != "live" ? 1 : 0;
  for (auto it = entries_.begin(); it != entries_.end() && ended > keep_;) {
    if (it->state == "live") {
      ++it;
      continue;
    }
    std::error_code ec;
    std::filesystem::remove(TakePath(it->id), ec);
    it = entries_.erase(it);
    --ended;
  }
}

nlohmann::json Sessions::List() const {
  std::lock_guard<std::mutex> lock(mu_);
  nlohmann::json out = nlohmann::json::array();
  for (const Entry& e : entries_)
    out.push_back(LiveSessionJson(e.id, e.started, e.state, e.rate_hz, e.samples, e.impacts));
  return out;
}

std::optional<std::string> Sessions::FinishedTake(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mu_);
  for (const Entry& e : entries_)
    if (e.id == id && e.state == "finished") return TakePath(id);
  return std::nullopt;
}

}  // namespace bouncecal::serve
