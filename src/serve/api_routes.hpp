// The routes of the server's API that do the work (api_routes.cpp), and what they share with the
// router (api.cpp): where a request's recording comes from. Private to src/serve.
#pragma once

#include <optional>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/serve/api.hpp"
#include "bouncecal/serve/requests.hpp"

namespace bouncecal::serve {

struct RouteContext {
  const ApiRequest& request;
  const std::string& dir;  // the request's own temporary directory
  Sessions* sessions;
  const ApiOptions& options;
  std::string route;  // "/api/analyze", for messages
};

// The recording of a request: a finished live take (take=ID) or the body.
struct SourceQuery {
  std::optional<std::string> take;
  std::optional<std::string> name;
};
SourceQuery TakeSourceQuery(Query& q);

struct Recording {
  std::string path;  // on the server (never shown)
  std::string name;  // shown in results and messages
};
// Throws Error(kInputMissing) for no body / an unknown take, Error(kUsage) for a malformed
// multipart body.
Recording OpenSource(const SourceQuery& source, const RouteContext& context);
// `e` with every mention of the recording's server path replaced by its name.
Error Named(const Error& e, const Recording& recording);

ApiResponse AnalyzeRoute(Query q, const RouteContext& context);
ApiResponse CalibrateRoute(Query q, const RouteContext& context);
ApiResponse ReportRoute(Query q, const RouteContext& context);
ApiResponse ExportRoute(Query q, const RouteContext& context);

// A JSON document as a response.
ApiResponse JsonResponse(const nlohmann::json& doc, int exit_code = 0);

}  // namespace bouncecal::serve
