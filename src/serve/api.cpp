// The server's routes (include/bouncecal/serve/api.hpp): the router, the sources of a
// request's recording, and the error responses.
#include "bouncecal/serve/api.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

#include "api_routes.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/serve/page.hpp"
#include "bouncecal/serve/query_options.hpp"

namespace bouncecal::serve {
namespace {

// A read-only view of a file's bytes.
class MappedFile {
 public:
  explicit MappedFile(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw Error(ErrorCode::kInternal, "the request body cannot be read");
    size_ = static_cast<std::size_t>(::lseek(fd, 0, SEEK_END));
    if (size_ > 0) {
      void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
      data_ = p == MAP_FAILED ? nullptr : static_cast<const char*>(p);
    }
    ::close(fd);
    if (size_ > 0 && data_ == nullptr)
      throw Error(ErrorCode::kInternal, "the request body cannot be mapped");
  }
  ~MappedFile() {
    if (data_ != nullptr) ::munmap(const_cast<char*>(data_), size_);
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  std::string_view view() const { return {data_, size_}; }

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
};

// ".wav" of "drop.WAV": a short alphanumeric extension (helps FFmpeg's probe), else "".
std::string SafeExtension(const std::string& name) {
  const std::size_t dot = name.rfind('.');
  if (dot == std::string::npos || name.size() - dot > 6) return "";
  std::string ext = ".";
  for (std::size_t i = dot + 1; i < name.size(); ++i) {
    const auto c = static_cast<unsigned char>(name[i]);
    if (!std::isalnum(c)) return "";
    ext += static_cast<char>(std::tolower(c));
  }
  return ext.size() > 1 ? ext : "";
}

ApiResponse SessionsRoute(Query q, const RouteContext& c) {
  q.Finish(c.route);
  return JsonResponse(c.sessions->List());
}

ApiResponse TakeRoute(const std::string& file, const RouteContext& c) {
  const std::string id = file.size() > 5 ? file.substr(0, file.size() - 5) : "";
  if (file.size() <= 5 || file.substr(file.size() - 5) != ".flac" || !IsSessionId(id))
    return ErrorResponse(404, static_cast<int>(ErrorCode::kUsage), "",
                         "no such take: a take's URL is /api/takes/ID.flac (32 hex digits)");
  const auto path = c.sessions->FinishedTake(id);
  if (!path)
    return ErrorResponse(404, static_cast<int>(ErrorCode::kInputMissing), "",
                         "no finished take " + id + " on this server");
  ApiResponse r;
  r.content_type = "audio/flac";
  r.file = *path;
  r.download_name = "take-" + id + ".flac";
  return r;
}

// `laws --json` (bouncecal.laws/1): the page's choice of law.
ApiResponse LawsRoute(Query q, const RouteContext& c) {
  q.Finish(c.route);
  std::vector<nlohmann::json> laws;
  for (const LawInfo& info : RegisteredLaws()) {
    const LawSpec spec = ExampleLawSpec(info.name);
    laws.push_back(LawListingJson(*CreateLaw(spec, Scene{}), info.summary, spec.expression));
  }
  return JsonResponse(LawsJson(laws));
}

ApiResponse PageRoute(Query q, const RouteContext& c) {
  q.TakeFlag("autostart");  // read by the page itself
  q.Finish(c.route);
  ApiResponse r;
  r.content_type = "text/html; charset=utf-8";
  r.body = std::string(PageHtml());
  return r;
}

}  // namespace

SourceQuery TakeSourceQuery(Query& q) { return {q.TakeString("take"), q.TakeString("name")}; }

Recording OpenSource(const SourceQuery& source, const RouteContext& c) {
  Recording rec;
  if (source.take) {
    if (!IsSessionId(*source.take))
      throw Error(ErrorCode::kUsage, "take=" + Abbreviate(*source.take) + ": not a take id");
    const auto path = c.sessions->FinishedTake(*source.take);
    if (!path) throw Error(ErrorCode::kInputMissing, "no finished take " + *source.take);
    rec.path = *path;
    rec.name = source.name ? DisplayName(*source.name) : "take-" + *source.take + ".flac";
    return rec;
  }
  if (c.request.body_path.empty() || c.request.body_bytes == 0)
    throw Error(ErrorCode::kInputMissing,
                c.route +
                    ": no recording: send the file as the request body (or as "
                    "multipart/form-data, or take=ID for a live take)");
  std::string name = source.name.value_or("");
  std::optional<UploadPart> part;
  if (IsMultipart(c.request.content_type)) {
    const MappedFile body(c.request.body_path);
    part = FindUpload(body.view(), c.request.content_type);
    if (name.empty()) name = part->filename;
    if (part->size == 0)
      throw Error(ErrorCode::kInputMissing, c.route + ": the uploaded file is empty");
    rec.path = c.dir + "/upload" + SafeExtension(DisplayName(name));
    std::ofstream out(rec.path, std::ios::binary);
    out.write(body.view().data() + part->offset, static_cast<std::streamsize>(part->size));
    if (!out.flush()) throw Error(ErrorCode::kInternal, "the upload could not be stored");
  } else {
    rec.path = c.dir + "/upload" + SafeExtension(DisplayName(name));
    std::filesystem::rename(c.request.body_path, rec.path);
  }
  rec.name = DisplayName(name.empty() ? "upload" : name);
  return rec;
}

Error Named(const Error& e, const Recording& recording) {
  std::string m = e.what();
  if (!recording.path.empty())
    for (std::size_t at; (at = m.find(recording.path)) != std::string::npos;)
      m.replace(at, recording.path.size(), recording.name);
  return Error(e.code(), QueryText(m));
}

ApiResponse JsonResponse(const nlohmann::json& doc, int exit_code) {
  ApiResponse r;
  r.body = DumpJson(doc, 2) + "\n";
  r.exit_code = exit_code;
  return r;
}

int HttpStatus(int exit_code) {
  switch (static_cast<ErrorCode>(exit_code)) {
    case ErrorCode::kUsage:
    case ErrorCode::kBadScene:
    case ErrorCode::kBadParameter:
    case ErrorCode::kInputMissing:
      return 400;
    case ErrorCode::kNotAudio:
      return 415;
    case ErrorCode::kBadSamples:
    case ErrorCode::kSilence:
    case ErrorCode::kNoBounces:
    case ErrorCode::kFitFailed:
    case ErrorCode::kSomeFailed:
    case ErrorCode::kFitIterationLimit:
    case ErrorCode::kFitPoorFit:
    case ErrorCode::kFitNotDeterminable:
      return 422;
    default:
      return 500;
  }
}

ApiResponse ErrorResponse(int status, int exit_code, const std::string& file,
                          const std::string& message) {
  ApiResponse r = JsonResponse(FailedInputJson(file, static_cast<ErrorCode>(exit_code), message));
  r.status = status;
  r.exit_code = exit_code;
  return r;
}

Api::Api(Sessions* sessions, const ApiOptions& options) : sessions_(sessions), options_(options) {}

ApiResponse Api::Handle(const ApiRequest& request, const std::string& request_dir) const {
  try {
    return Route(request, request_dir);
  } catch (const Error& e) {
    return ErrorResponse(HttpStatus(e.exit_code()), e.exit_code(), "", QueryText(e.what()));
  } catch (const std::exception& e) {
    return ErrorResponse(500, static_cast<int>(ErrorCode::kInternal), "",
                         std::string("internal error: ") + e.what());
  }
}

ApiResponse Api::Route(const ApiRequest& request, const std::string& request_dir) const {
  const Target t = ParseTarget(request.target);
  RouteContext c{request, request_dir, sessions_, options_, t.path};
  Query q(t.query);
  struct Route {
    const char* method;
    const char* path;
    ApiResponse (*run)(Query, const RouteContext&);
  };
  static constexpr Route kRoutes[] = {
      {"GET", "/", PageRoute},
      {"GET", "/index.html", PageRoute},
      {"GET", "/api/sessions", SessionsRoute},
      {"GET", "/api/laws", LawsRoute},
      {"POST", "/api/analyze", AnalyzeRoute},
      {"POST", "/api/calibrate", CalibrateRoute},
      {"POST", "/api/report", ReportRoute},
      {"POST", "/api/export", ExportRoute},
  };
  constexpr std::string_view kTakes = "/api/takes/";
  if (t.path.rfind(kTakes, 0) == 0 && t.path.size() > kTakes.size()) {
    if (request.method != "GET")
      return ErrorResponse(405, static_cast<int>(ErrorCode::kUsage), "",
                           request.method + " " + t.path + ": only GET");
    q.Finish(t.path);
    return TakeRoute(t.path.substr(kTakes.size()), c);
  }
  bool path_known = false;
  for (const Route& r : kRoutes) {
    if (t.path != r.path) continue;
    path_known = true;
    if (request.method == r.method) return r.run(std::move(q), c);
  }
  if (path_known || t.path == "/api/live")
    return ErrorResponse(
        405, static_cast<int>(ErrorCode::kUsage), "",
        Abbreviate(request.method) + " " + t.path +
            (t.path == "/api/live" ? ": a WebSocket (GET with Upgrade)" : ": method not allowed"));
  return ErrorResponse(404, static_cast<int>(ErrorCode::kUsage), "",
                       "no route " + t.path + " (docs/serve.md lists them)");
}

}  // namespace bouncecal::serve
