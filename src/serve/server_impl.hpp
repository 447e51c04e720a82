// The server's state (server.cpp: accepting, the connections' threads, stopping) and what one
// connection's thread runs (connection.cpp). Private to src/serve.
#pragma once

#include <atomic>
#include <chrono>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>

#include "bouncecal/serve/api.hpp"
#include "bouncecal/serve/server.hpp"
#include "bouncecal/serve/sessions.hpp"

namespace bouncecal::serve {

using Tcp = boost::asio::ip::tcp;

// One connection: its socket's descriptor (to close it from the reaper or Stop), when it was
// last heard from, and whether a request is being worked on (never idle then).
struct Connection {
  int fd = -1;
  std::atomic<std::int64_t> last_active_ms{0};
  std::atomic<bool> busy{false};
  std::atomic<bool> done{false};
  std::thread thread;
  void Touch();
};

struct Server::Impl {
  ServeOptions options;
  boost::asio::io_context io;
  Tcp::acceptor acceptor{io};
  std::string root;  // the server's temporary directory
  std::unique_ptr<Sessions> sessions;
  std::unique_ptr<Api> api;
  std::atomic<bool> stopping{false};
  std::mutex mu;
  std::list<std::shared_ptr<Connection>> connections;
  std::thread reaper;
  int port = 0;

  void Reap();  // closes idle connections, joins finished ones (every 0.2 s until stopping)
};

std::int64_t NowMs();

// Serves one connection until it closes (HTTP requests, or one live stream).
void ServeConnection(Server::Impl& server, Tcp::socket& socket, Connection& connection);

}  // namespace bouncecal::serve
