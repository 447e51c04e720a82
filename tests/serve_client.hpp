// A small synchronous client of `bouncecal serve` for the tests (Boost.Beast): HTTP requests,
// raw bytes, and a WebSocket to /api/live.
#pragma once

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>

namespace bouncecal::testing_util {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

struct HttpReply {
  int status = 0;
  std::string body;
  std::string content_type;
  std::string exit_code;    // X-Bouncecal-Exit-Code
  std::string disposition;  // Content-Disposition
  nlohmann::json json() const { return nlohmann::json::parse(body, nullptr, false); }
};

inline tcp::socket Connect(net::io_context& io, int port) {
  tcp::socket s(io);
  s.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(port)));
  return s;
}

inline HttpReply Request(int port, http::verb method, const std::string& target,
                         const std::string& body = "",
                         const std::string& content_type = "application/octet-stream") {
  net::io_context io;
  tcp::socket s = Connect(io, port);
  http::request<http::string_body> req{method, target, 11};
  req.set(http::field::host, "127.0.0.1:" + std::to_string(port));
  if (!body.empty()) req.set(http::field::content_type, content_type);
  req.body() = body;
  req.prepare_payload();
  beast::error_code ec;
  http::write(s, req, ec);
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> res;
  res.body_limit(1u << 30);
  http::read(s, buffer, res, ec);
  HttpReply out;
  if (ec) return out;
  out.status = res.get().result_int();
  out.body = res.get().body();
  out.content_type = std::string(res.get()[http::field::content_type]);
  out.exit_code = std::string(res.get()["X-Bouncecal-Exit-Code"]);
  out.disposition = std::string(res.get()[http::field::content_disposition]);
  return out;
}

inline HttpReply Get(int port, const std::string& target) {
  return Request(port, http::verb::get, target);
}
inline HttpReply Post(int port, const std::string& target, const std::string& body,
                      const std::string& content_type = "application/octet-stream") {
  return Request(port, http::verb::post, target, body, content_type);
}

// Sends bytes as they are and returns whatever comes back until the server closes (or 10 s).
inline std::string Raw(int port, const std::string& bytes, bool close_write = true) {
  net::io_context io;
  tcp::socket s = Connect(io, port);
  beast::error_code ec;
  net::write(s, net::buffer(bytes), ec);
  if (close_write) s.shutdown(tcp::socket::shutdown_send, ec);
  std::string out;
  char buf[4096];
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < until) {
    const std::size_t n = s.read_some(net::buffer(buf), ec);
    if (ec) break;
    out.append(buf, n);
  }
  return out;
}

// A live stream: Open (the upgrade, with the query), then Text / Binary, and the messages.
class LiveClient {
 public:
  explicit LiveClient(int port, const std::string& query = "") : ws_(Connect(io_, port)) {
    ws_.handshake("127.0.0.1:" + std::to_string(port), "/api/live" + query, ec_);
  }
  bool ok() const { return !ec_; }
  bool Text(const std::string& text) {
    ws_.text(true);
    ws_.write(net::buffer(text), ec_);
    return !ec_;
  }
  bool Binary(const std::string& bytes) {
    ws_.binary(true);
    ws_.write(net::buffer(bytes), ec_);
    return !ec_;
  }
  bool Samples(const float* x, std::size_t n) {
    return Binary(std::string(reinterpret_cast<const char*>(x), n * sizeof(float)));
  }
  // The next message (null when the stream closed).
  nlohmann::json Next() {
    beast::flat_buffer b;
    ws_.read(b, ec_);
    if (ec_) return nullptr;
    return nlohmann::json::parse(beast::buffers_to_string(b.data()), nullptr, false);
  }
  // Whether a message is waiting, without blocking.
  bool Ready() { return ws_.next_layer().available() > 0; }
  websocket::close_reason reason() const { return ws_.reason(); }
  const beast::error_code& error() const { return ec_; }

 private:
  net::io_context io_;
  beast::error_code ec_;
  websocket::stream<tcp::socket> ws_;
};

}  // namespace bouncecal::testing_util
