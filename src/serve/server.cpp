// `bouncecal serve`'s server (include/bouncecal/serve/server.hpp): the listening socket, one
// thread per connection, the reaper of idle connections, and stopping.
#include "bouncecal/serve/server.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/v6_only.hpp>
#include <boost/asio/write.hpp>

#include "bouncecal/core/error.hpp"
#include "server_impl.hpp"

namespace bouncecal::serve {

std::int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void Connection::Touch() { last_active_ms = NowMs(); }

bool ServeOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& what) {
    if (error != nullptr) *error = "ServeOptions::" + what;
    return false;
  };
  if (port < 0 || port > 65535) return fail("port " + std::to_string(port) + ": expected 0..65535");
  if (max_body_bytes < 1024) return fail("max_body_bytes: at least 1 kB");
  if (max_connections < 1 || max_connections > 4096)
    return fail("max_connections " + std::to_string(max_connections) + ": expected 1..4096");
  if (!(idle_timeout_s >= 0.1 && idle_timeout_s <= 86400.0))
    return fail("idle_timeout_s: expected 0.1 s .. 1 day");
  if (jobs < 1 || jobs > 256) return fail("jobs " + std::to_string(jobs) + ": expected 1..256");
  if (keep_takes < 1 || keep_takes > 10000) return fail("keep_takes: expected 1..10000");
  if (live.max_frame_bytes < 4) return fail("live.max_frame_bytes: at least one sample");
  return live.live.IsValid(error);
}

bool IsLoopback(const std::string& host) {
  if (host == "localhost") return true;
  boost::system::error_code ec;
  const auto a = boost::asio::ip::make_address(host, ec);
  return !ec && a.is_loopback();
}

namespace {

std::string MakeRoot() {
  std::string tmpl = (std::filesystem::temp_directory_path() / "bouncecal-serve-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr)
    throw Error(ErrorCode::kOutput, "cannot create the server's temporary directory under " +
                                        std::filesystem::temp_directory_path().string());
  return tmpl;
}

}  // namespace

Server::Server(const ServeOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.options = options;
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  const std::string host = options.host == "localhost" ? "127.0.0.1" : options.host;
  boost::system::error_code ec;
  const auto address = boost::asio::ip::make_address(host, ec);
  const std::string where = options.host + ":" + std::to_string(options.port);
  if (ec)
    throw Error(ErrorCode::kUsage, options.host + ": not an IP address (" + ec.message() + ")");
  const Tcp::endpoint endpoint(address, static_cast<unsigned short>(options.port));
  s.acceptor.open(endpoint.protocol(), ec);
  if (!ec) s.acceptor.set_option(boost::asio::socket_base::reuse_address(true), ec);
  if (!ec) s.acceptor.bind(endpoint, ec);
  if (!ec) s.acceptor.listen(boost::asio::socket_base::max_listen_connections, ec);
  if (ec) throw Error(ErrorCode::kUsage, where + ": cannot listen there (" + ec.message() + ")");
  s.port = s.acceptor.local_endpoint().port();
  s.root = MakeRoot();
  s.sessions = std::make_unique<Sessions>(s.root + "/takes", options.keep_takes);
  s.api = std::make_unique<Api>(s.sessions.get(), ApiOptions{.jobs = options.jobs});
  s.reaper = std::thread([&s] { s.Reap(); });
}

Server::~Server() {
  Stop();
  Impl& s = *impl_;
  if (s.reaper.joinable()) s.reaper.join();
  std::list<std::shared_ptr<Connection>> left;
  {
    std::lock_guard<std::mutex> lock(s.mu);
    left.swap(s.connections);
  }
  for (auto& c : left)
    if (c->thread.joinable()) c->thread.join();
  s.sessions.reset();
  std::error_code ec;
  std::filesystem::remove_all(s.root, ec);
}

int Server::port() const { return impl_->port; }

std::string Server::url() const {
  const std::string& h = impl_->options.host;
  const bool v6 = h.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + h + "]" : h) + ":" + std::to_string(impl_->port) + "/";
}

std::string Server::temp_dir() const { return impl_->root; }

void Server::Stop() {
  Impl& s = *impl_;
  s.stopping = true;
  std::lock_guard<std::mutex> lock(s.mu);
  for (auto& c : s.connections)
    if (!c->done) ::shutdown(c->fd, SHUT_RDWR);
}

void Server::Run() {
  Impl& s = *impl_;
  const int listen_fd = s.acceptor.native_handle();
  while (!s.stopping) {
    pollfd p{listen_fd, POLLIN, 0};
    if (::poll(&p, 1, 200) <= 0) continue;  // checks `stopping` 5 times a second
    boost::system::error_code ec;
    Tcp::socket socket(s.io);
    s.acceptor.accept(socket, ec);
    if (ec) continue;
    auto c = std::make_shared<Connection>();
    c->fd = socket.native_handle();
    c->Touch();
    std::lock_guard<std::mutex> lock(s.mu);
    std::size_t open = 0;
    for (const auto& other : s.connections) open += other->done ? 0 : 1;
    if (s.stopping || open >= static_cast<std::size_t>(s.options.max_connections)) {
      const std::string body =
          "{\"schema\": \"bouncecal.error/1\", \"file\": \"\", \"error\": {\"code\": \"usage\", "
          "\"exit_code\": 2, \"message\": \"too many connections: try again later\"}}\n";
      const std::string busy =
          "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
          "Connection: close\r\nContent-Length: " +
          std::to_string(body.size()) + "\r\n\r\n" + body;
      boost::asio::write(socket, boost::asio::buffer(busy), ec);
      socket.shutdown(Tcp::socket::shutdown_both, ec);
      continue;
    }
    s.connections.push_back(c);
    c->thread = std::thread([&s, c, sock = std::move(socket)]() mutable {
      try {
        ServeConnection(s, sock, *c);
      } catch (...) {
        // A connection's failure ends that connection only.
      }
      // Done before the descriptor is closed (when `sock` goes): Stop and the reaper shut down
      // only connections not done, so never a descriptor number reused by a newer one.
      std::lock_guard<std::mutex> done_lock(s.mu);
      c->done = true;
    });
  }
  // Stopping: close every connection, then wait for their threads.
  Stop();
  std::list<std::shared_ptr<Connection>> left;
  {
    std::lock_guard<std::mutex> lock(s.mu);
    left.swap(s.connections);
  }
  for (auto& c : left)
    if (c->thread.joinable()) c->thread.join();
}

void Server::Impl::Reap() {
  const auto idle_ms = static_cast<std::int64_t>(std::ceil(options.idle_timeout_s * 1000.0));
  while (!stopping) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    std::list<std::shared_ptr<Connection>> finished;
    {
      std::lock_guard<std::mutex> lock(mu);
      const std::int64_t now = NowMs();
      for (auto it = connections.begin(); it != connections.end();) {
        Connection& c = **it;
        if (c.done) {
          finished.push_back(*it);
          it = connections.erase(it);
          continue;
        }
        if (!c.busy && now - c.last_active_ms > idle_ms) ::shutdown(c.fd, SHUT_RDWR);
        ++it;
      }
    }
    for (auto& c : finished)
      if (c->thread.joinable()) c->thread.join();
  }
}

}  // namespace bouncecal::serve
