// What the server parses from the network (src/serve): request targets and their query as the
// library's options, multipart/form-data bodies, the live stream's messages through a whole
// LiveSession (start, samples, stop), and a request through the API's router. The first byte
// chooses which; the rest is the input. Contract (fuzz_util.hpp): a result or bouncecal::Error.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include "bouncecal/core/error.hpp"
#include "bouncecal/serve/api.hpp"
#include "bouncecal/serve/live_session.hpp"
#include "bouncecal/serve/query_options.hpp"
#include "bouncecal/serve/requests.hpp"
#include "bouncecal/serve/sessions.hpp"

namespace {

using namespace bouncecal;
using namespace bouncecal::serve;

// One directory per process for takes and request bodies.
const std::string& Dir() {
  static const std::string dir = [] {
    const std::string d = "/tmp/bouncecal_fuzz_serve_" + std::to_string(::getpid());
    std::filesystem::create_directories(d + "/request");
    return d;
  }();
  return dir;
}

void FuzzQuery(std::string_view in) {
  const Target t = ParseTarget(in);
  serve::Query q(t.query);
  SceneOverrides scene = TakeSceneQuery(q, true);
  const DropInputOptions drops = TakeDropQuery(q);
  (void)drops;
  scene.law.clear();
  const GivenScene gs = ResolveGivenScene(scene);
  (void)TakeCalibrationQuery(q, gs, 1);
  q.Finish(t.path);
}

// "content type\nbody"
void Multipart(std::string_view in) {
  const std::size_t nl = in.find('\n');
  if (nl == std::string_view::npos) return;
  const UploadPart p = FindUpload(in.substr(nl + 1), in.substr(0, nl));
  if (p.offset + p.size > in.size() - nl - 1) __builtin_trap();  // a part must lie in the body
  (void)DisplayName(p.filename);
}

// Messages separated by 0xFF 0xFE; a message starting with 'b' is binary, otherwise text.
void Live(std::string_view in) {
  static Sessions sessions(Dir() + "/takes", 2);
  LiveSessionOptions o;
  o.max_frame_bytes = 4096;
  LiveSession s(&sessions, {}, o);
  std::size_t at = 0;
  while (at <= in.size() && !s.done()) {
    std::size_t end = in.find("\xff\xfe", at);
    if (end == std::string_view::npos) end = in.size();
    const std::string_view m = in.substr(at, end - at);
    if (!m.empty() && m.front() == 'b') {
      s.OnBinary(m.substr(1));
    } else {
      s.OnText(m);
    }
    at = end + 2;
  }
}

// "METHOD TARGET\ncontent type\nbody"
void FuzzApi(std::string_view in) {
  static Sessions sessions(Dir() + "/takes", 2);
  static const serve::Api api(&sessions, ApiOptions{});
  const std::size_t a = in.find(' '), b = in.find('\n'), c = in.find('\n', b + 1);
  if (a == std::string_view::npos || b == std::string_view::npos || c == std::string_view::npos ||
      a > b)
    return;
  ApiRequest r;
  r.method = std::string(in.substr(0, a));
  r.target = std::string(in.substr(a + 1, b - a - 1));
  r.content_type = std::string(in.substr(b + 1, c - b - 1));
  const std::string_view body = in.substr(c + 1);
  const std::string request_dir = Dir() + "/request";
  if (!body.empty()) {
    r.body_path = request_dir + "/body";
    std::FILE* f = std::fopen(r.body_path.c_str(), "wb");
    if (f == nullptr) return;
    std::fwrite(body.data(), 1, body.size(), f);
    std::fclose(f);
    r.body_bytes = body.size();
  }
  const ApiResponse response = api.Handle(r, request_dir);  // never throws
  if (response.status < 100 || response.status > 599) __builtin_trap();
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(request_dir, ec))
    std::filesystem::remove_all(e.path(), ec);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string_view in(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    switch (data[0] % 7) {
      case 0:
        FuzzQuery(in);
        break;
      case 1:
        Multipart(in);
        break;
      case 2:
        (void)ParseLiveStart(in);
        break;
      case 3:
        (void)ParseLiveControl(in);
        break;
      case 4:
        (void)ParseLiveSamples(in, 4096);
        break;
      case 5:
        Live(in);
        break;
      default:
        FuzzApi(in);
        break;
    }
  } catch (const Error&) {
  }
  return 0;
}
