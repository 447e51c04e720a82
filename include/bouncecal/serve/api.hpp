// bouncecal/serve/api.hpp — the server's HTTP routes, apart from the network: a request (its
// body already in a file of the request's own temporary directory) in, a response out. Each route
// makes the library calls the matching command makes (docs/serve.md):
//   GET  /                      the page (page.hpp)
//   POST /api/analyze           body: a recording    -> `analyze --json`     (bouncecal.analysis/1)
//   POST /api/calibrate         body: a recording    -> `calibrate --json`   (bouncecal.params/2,
//                                                       law=all: bouncecal.law_comparison/2)
//   POST /api/report            body: a recording    -> `report -o`          (text/html)
//   POST /api/export?to=T       body: a params file  -> `export --to T`      (application/zip)
//   GET  /api/laws                                   -> `laws --json`        (bouncecal.laws/1)
//   GET  /api/sessions                               -> the live sessions
//   (bouncecal.live_session/1) GET  /api/takes/ID.flac                          -> a finished live
//   take (audio/flac)
// The recording routes take `take=ID` (a finished live take) instead of a body, and `name` (the
// recording's name in the results; a multipart upload's filename otherwise). Errors are
// bouncecal.error/1 objects with the HTTP status of their kind; the exit code the command would
// have returned is in the header X-Bouncecal-Exit-Code (a fit that did not converge: 200 with
// the document that records its outcome, as `calibrate` writes it, and the outcome's code).
//
//   Api api(&sessions, ApiOptions{});
//   ApiResponse r = api.Handle({"POST", "/api/analyze?height=0.2", "audio/wav", body, size}, dir);
#pragma once

#include <cstddef>
#include <string>

#include "bouncecal/serve/sessions.hpp"

namespace bouncecal::serve {

struct ApiRequest {
  std::string method;        // "GET", "POST", ...
  std::string target;        // "/api/analyze?height=0.2" as received
  std::string content_type;  // of the body
  std::string body_path;     // the body, in a file of the request's directory ("" = none)
  std::size_t body_bytes = 0;
};

struct ApiResponse {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
  std::string file;           // sent instead of body when set (a take)
  std::string download_name;  // Content-Disposition: attachment; filename=...
  int exit_code = 0;          // X-Bouncecal-Exit-Code
};

struct ApiOptions {
  int jobs = 1;  // threads of a fit (CalibrationOptions::threads, CompareLaws)
};

class Api {
 public:
  Api(Sessions* sessions, const ApiOptions& options);
  // Never throws for a bad request: every Error becomes an error response; anything else is an
  // internal error (500).
  ApiResponse Handle(const ApiRequest& request, const std::string& request_dir) const;

 private:
  ApiResponse Route(const ApiRequest& request, const std::string& request_dir) const;
  Sessions* sessions_;
  ApiOptions options_;
};

// The HTTP status of an error code (400 for a bad request, 413 too large, 415 not audio, 422
// for input that has no usable result, 500 for internal errors).
int HttpStatus(int exit_code);
// The error document: bouncecal.error/1 {"schema", "file", "error": {code, exit_code, message}}.
ApiResponse ErrorResponse(int status, int exit_code, const std::string& file,
                          const std::string& message);

}  // namespace bouncecal::serve
