// bouncecal/serve/server.hpp — `bouncecal serve`: a local HTTP + WebSocket server (Boost.Beast)
// for the page (page.hpp), the API (api.hpp) and live streams (live_session.hpp).
//
// Each connection is served by a thread of its own, synchronously: a request is read (its body
// streamed into a file of a temporary directory of its own, removed after the response), handed
// to the API, answered; a WebSocket upgrade to /api/live becomes a live session on that thread.
// Bodies above max_body_bytes are refused with 413 before they are read; a connection silent
// for idle_timeout_s (between requests, or between a live stream's messages) is closed; beyond
// max_connections a new one gets 503. The server's files (uploads, takes) live in one directory
// of its own under TMPDIR, removed when it stops. Stop() (from any thread: the CLI's signal
// thread on Ctrl-C) ends the accept loop and closes every connection; Run() then returns.
//
//   Server server(ServeOptions{.port = 0});   // binds 127.0.0.1 on a free port
//   std::thread t([&] { server.Run(); });
//   ... server.url() ...
//   server.Stop();  t.join();
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "bouncecal/serve/live_session.hpp"

namespace bouncecal::serve {

struct ServeOptions {
  std::string host = "127.0.0.1";  // loopback: only this machine can connect
  int port = 8765;                 // 0: a free port (see Server::port)
  // Largest request body: a WAV of an hour at 48 kHz, 16-bit mono is 346 MB.
  std::size_t max_body_bytes = std::size_t{512} << 20;
  int max_connections = 64;
  double idle_timeout_s = 60.0;
  int jobs = 1;  // threads of one fit (ApiOptions::jobs)
  LiveSessionOptions live;
  int keep_takes = 16;  // finished live sessions (and takes) kept (Sessions)
  bool IsValid(std::string* error) const;
};

class Server {
 public:
  // Binds and listens. Throws Error(kUsage) naming the address when it cannot (in use, not an
  // address of this machine), Error(kOutput) when its temporary directory cannot be made.
  explicit Server(const ServeOptions& options);
  ~Server();  // Stop(), wait for the connections, remove the temporary directory
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  int port() const;
  std::string url() const;  // "http://127.0.0.1:8765/"
  // Accepts connections until Stop(); returns once every connection has ended.
  void Run();
  // Thread-safe; returns at once (Run returns when the connections are closed).
  void Stop();
  // The directory that holds the uploads and takes (for tests: it must be empty of uploads
  // between requests).
  std::string temp_dir() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// True for an address only this machine can reach (127.0.0.0/8, ::1, "localhost").
bool IsLoopback(const std::string& host);

}  // namespace bouncecal::serve
