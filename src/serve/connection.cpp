// One connection of the server (server_impl.hpp): HTTP requests read with Boost.Beast, their
// bodies streamed to a temporary directory of their own, answered by the API; or a WebSocket
// upgrade to /api/live, served as one live session.
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <optional>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/live_json.hpp"
#include "bouncecal/serve/requests.hpp"
#include "server_impl.hpp"

namespace bouncecal::serve {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

constexpr std::size_t kHeaderLimit = 16 * 1024;
// Beast's own limit on a WebSocket message, above the live session's (which answers with an
// error message): past it Beast closes with 1009 and no message.
constexpr std::size_t kWebSocketSlack = 64 * 1024;

// A temporary directory of one request, removed with everything in it.
class RequestDir {
 public:
  explicit RequestDir(const std::string& root) {
    std::string tmpl = root + "/request-XXXXXX";
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw Error(ErrorCode::kOutput, "cannot create a request's temporary directory");
    path_ = tmpl;
  }
  ~RequestDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  RequestDir(const RequestDir&) = delete;
  RequestDir& operator=(const RequestDir&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// The headers every response carries. The page may run only its own inline script and the
// audio worklet it makes from it, and connect only to this server: nothing from the network.
template <class Body>
void SetHeaders(http::response<Body>* res, const ApiResponse& r, bool keep_alive) {
  res->set(http::field::server, "bouncecal/" BOUNCECAL_VERSION);
  res->set(http::field::content_type, r.content_type);
  res->set(http::field::cache_control, "no-store");
  res->set("X-Content-Type-Options", "nosniff");
  res->set("X-Bouncecal-Exit-Code", std::to_string(r.exit_code));
  res->set("Content-Security-Policy",
           "default-src 'none'; script-src 'unsafe-inline' blob:; style-src 'unsafe-inline'; "
           "img-src data: blob:; media-src blob: 'self'; connect-src 'self'; worker-src blob:");
  if (!r.download_name.empty())
    res->set(http::field::content_disposition,
             "attachment; filename=\"" + DisplayName(r.download_name) + "\"");
  res->keep_alive(keep_alive);
}

// Writes the API's response; false when the connection failed.
bool Respond(Tcp::socket& socket, const ApiResponse& r, unsigned version, bool keep_alive) {
  beast::error_code ec;
  if (!r.file.empty()) {
    http::response<http::file_body> res{static_cast<http::status>(r.status), version};
    res.body().open(r.file.c_str(), beast::file_mode::scan, ec);
    if (!ec) {
      SetHeaders(&res, r, keep_alive);
      res.prepare_payload();
      http::write(socket, res, ec);
      return !ec;
    }
  }
  http::response<http::string_body> res{static_cast<http::status>(r.status), version};
  SetHeaders(&res, r, keep_alive);
  res.body() = r.file.empty() ? r.body : "";
  res.prepare_payload();
  http::write(socket, res, ec);
  return !ec;
}

// After a response that ends the connection early (the request was not read to its end): stop
// sending, then read and discard what the client still sends for a moment, so that closing
// does not reset the connection before the client has read the response.
void DrainAndClose(Tcp::socket& socket) {
  beast::error_code ec;
  socket.shutdown(Tcp::socket::shutdown_send, ec);
  const std::int64_t until = NowMs() + 2000;
  std::size_t drained = 0;
  char sink[65536];
  while (drained < (std::size_t{64} << 20)) {
    const std::int64_t left = until - NowMs();
    if (left <= 0) break;
    pollfd p{socket.native_handle(), POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left)) <= 0) break;
    const ssize_t n = ::recv(socket.native_handle(), sink, sizeof sink, MSG_DONTWAIT);
    if (n <= 0) break;
    drained += static_cast<std::size_t>(n);
  }
}

bool RespondError(Tcp::socket& socket, int status, ErrorCode code, const std::string& message,
                  unsigned version = 11) {
  const bool ok =
      Respond(socket, ErrorResponse(status, static_cast<int>(code), "", message), version, false);
  DrainAndClose(socket);
  return ok;
}

void Send(websocket::stream<Tcp::socket&>& ws, const nlohmann::json& m, beast::error_code& ec) {
  ws.text(true);
  ws.write(boost::asio::buffer(DumpJson(m)), ec);
}

// A live stream on this connection (WebSocket /api/live). A bad query is refused before the
// upgrade (HTTP 400); a bad message closes this stream only, after an error message.
void ServeLive(Server::Impl& s, Tcp::socket& socket, Connection& conn,
               const http::request<http::empty_body>& req) {
  std::unique_ptr<LiveSession> session;
  try {
    const Target t = ParseTarget(std::string(req.target()));
    if (t.path != "/api/live") {
      RespondError(socket, 404, ErrorCode::kUsage,
                   "no WebSocket at " + t.path + " (it is /api/live)");
      return;
    }
    // A page of another site must not stream to this one (the browser sends its Origin).
    const auto origin = req.find(http::field::origin);
    const auto host = req.find(http::field::host);
    if (origin != req.end() && (host == req.end() || std::string(origin->value()) !=
                                                         "http://" + std::string(host->value())))
      throw Error(ErrorCode::kUsage, "live: a page of another origin may not stream here");
    session = std::make_unique<LiveSession>(s.sessions.get(), t.query, s.options.live);
  } catch (const Error& e) {
    RespondError(socket, 400, e.code(), e.what());
    return;
  }
  websocket::stream<Tcp::socket&> ws(socket);
  ws.read_message_max(s.options.live.max_frame_bytes + kWebSocketSlack);
  ws.set_option(websocket::stream_base::decorator([](websocket::response_type& res) {
    res.set(http::field::server, "bouncecal/" BOUNCECAL_VERSION);
  }));
  beast::error_code ec;
  ws.accept(req, ec);
  if (ec) return;
  for (;;) {
    beast::flat_buffer buffer;
    ws.read(buffer, ec);
    if (ec) return;  // closed, lost, idle too long, or too large: the session fails
    conn.Touch();
    const std::string_view data(static_cast<const char*>(buffer.data().data()), buffer.size());
    std::vector<nlohmann::json> out;
    conn.busy = true;
    try {
      out = ws.got_text() ? session->OnText(data) : session->OnBinary(data);
    } catch (const Error& e) {
      conn.busy = false;
      Send(ws, LiveErrorJson(e.code(), e.what()), ec);
      websocket::close_reason why(websocket::close_code::policy_error);
      why.reason = Abbreviate(e.what(), 100);
      if (!ec) ws.close(why, ec);
      return;
    }
    conn.busy = false;
    for (const nlohmann::json& m : out) {
      Send(ws, m, ec);
      if (ec) return;
    }
    if (session->done()) {
      ws.close(websocket::close_code::normal, ec);
      return;
    }
  }
}

// Reads the body into the request's directory; the error response when it cannot.
std::optional<std::pair<int, std::string>> ReadBody(Tcp::socket& socket, beast::flat_buffer& buffer,
                                                    http::request_parser<http::file_body>& parser,
                                                    Connection& conn, std::size_t limit) {
  beast::error_code ec;
  while (!parser.is_done()) {
    http::read_some(socket, buffer, parser, ec);
    if (ec) break;
    conn.Touch();
  }
  if (ec == http::error::body_limit)
    return std::make_pair(413, "request body larger than the server's limit of " +
                                   std::to_string(limit >> 20) + " MB");
  if (ec) return std::make_pair(400, "request body incomplete or malformed (" + ec.message() + ")");
  return std::nullopt;
}

}  // namespace

void ServeConnection(Server::Impl& s, Tcp::socket& socket, Connection& conn) {
  beast::flat_buffer buffer;
  const std::size_t limit = s.options.max_body_bytes;
  for (;;) {
    http::request_parser<http::empty_body> head;
    head.header_limit(kHeaderLimit);
    head.body_limit(limit);
    beast::error_code ec;
    http::read_header(socket, buffer, head, ec);
    if (ec == http::error::end_of_stream || ec == boost::asio::error::eof ||
        ec == boost::asio::error::connection_reset || ec == boost::asio::error::not_connected ||
        ec == boost::asio::error::operation_aborted)
      return;
    if (ec == http::error::header_limit) {
      RespondError(socket, 431, ErrorCode::kUsage, "request headers larger than 16 kB");
      return;
    }
    if (ec == http::error::body_limit) {
      RespondError(
          socket, 413, ErrorCode::kUsage,
          "request body larger than the server's limit of " + std::to_string(limit >> 20) + " MB");
      return;
    }
    if (ec) {
      RespondError(socket, 400, ErrorCode::kUsage, "malformed request (" + ec.message() + ")");
      return;
    }
    conn.Touch();
    const http::request<http::empty_body>& req = head.get();
    if (websocket::is_upgrade(req)) return ServeLive(s, socket, conn, req);
    const unsigned version = req.version();
    const bool keep_alive = req.keep_alive();
    // The request's directory goes before the response does (the response is in memory).
    std::optional<RequestDir> dir(std::in_place, s.root);
    ApiRequest ar;
    ar.method = std::string(req.method_string());
    ar.target = std::string(req.target());
    if (auto it = req.find(http::field::content_type); it != req.end())
      ar.content_type = std::string(it->value());
    http::request_parser<http::file_body> parser(std::move(head));
    parser.body_limit(limit);
    const std::string body = dir->path() + "/body";
    parser.get().body().open(body.c_str(), beast::file_mode::write, ec);
    if (ec) {
      dir.reset();
      RespondError(socket, 500, ErrorCode::kInternal, "cannot store the request body");
      return;
    }
    if (const auto failed = ReadBody(socket, buffer, parser, conn, limit)) {
      parser.get().body().close();
      dir.reset();
      RespondError(socket, failed->first, ErrorCode::kUsage, failed->second, version);
      return;
    }
    parser.get().body().close();
    ar.body_bytes = static_cast<std::size_t>(std::filesystem::file_size(body));
    ar.body_path = body;
    conn.busy = true;
    const ApiResponse r = s.api->Handle(ar, dir->path());
    dir.reset();
    conn.busy = false;
    conn.Touch();
    if (!Respond(socket, r, version, keep_alive) || !keep_alive || s.stopping) return;
  }
}

}  // namespace bouncecal::serve
