// `bouncecal serve [--port N] [--host ADDR] [--open]`: the page and the API on a local server
// (src/serve, docs/serve.md). Flags -> ServeOptions; Ctrl-C (SIGINT) or SIGTERM stops it
// cleanly: the connections are closed, the uploads and takes removed, exit 0.
//
//   bouncecal serve                 # http://127.0.0.1:8765/ (this machine only)
//   bouncecal serve --port 0        # a free port, printed on stderr
//   bouncecal serve --host 0.0.0.0  # a lab network: everyone on it can use the server
#include <pthread.h>
#include <spawn.h>
#include <sys/wait.h>

#include <csignal>
#include <cstdio>
#include <thread>

#include "bouncecal/core/error.hpp"
#include "bouncecal/serve/server.hpp"
#include "commands.hpp"
#include "output.hpp"

extern char** environ;

namespace bouncecal::cli {
namespace {

struct ServeArgs {
  int port = 8765;
  std::string host = "127.0.0.1";
  bool open = false;
  double max_body_mb = 512.0;
  int jobs = DefaultJobs();
  double idle_timeout_s = 60.0;
};

// The URL in the desktop's browser (xdg-open), without waiting for it.
void OpenInBrowser(const std::string& url) {
  pid_t pid = 0;
  const char* argv[] = {"xdg-open", url.c_str(), nullptr};
  if (::posix_spawnp(&pid, "xdg-open", nullptr, nullptr, const_cast<char* const*>(argv), environ) !=
      0) {
    std::fprintf(stderr,
                 "bouncecal: warning [no_browser]: --open: xdg-open is not available; "
                 "open %s by hand\n",
                 url.c_str());
    return;
  }
  std::thread([pid] { ::waitpid(pid, nullptr, 0); }).detach();
}

void Run(const ServeArgs& a) {
  serve::ServeOptions o;
  o.port = a.port;
  o.host = a.host;
  if (!(a.max_body_mb >= 1.0 && a.max_body_mb <= 1 << 20))
    throw Error(ErrorCode::kUsage, "--max-body-mb: expected 1 to 1048576");
  o.max_body_bytes = static_cast<std::size_t>(a.max_body_mb * 1048576.0);
  o.jobs = a.jobs;
  o.idle_timeout_s = a.idle_timeout_s;
  // SIGINT and SIGTERM go to one thread that stops the server (every thread the server starts
  // inherits the mask, so none of them is interrupted mid-request).
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  serve::Server server(o);  // Error(kUsage) naming the address when it cannot listen
  if (!serve::IsLoopback(a.host))
    std::fprintf(stderr,
                 "bouncecal: warning [serve_network]: listening on %s: anyone on that network "
                 "can use this server (upload recordings, stream, download the takes)\n",
                 a.host.c_str());
  std::fprintf(stderr, "bouncecal: serving %s (Ctrl-C stops it)\n", server.url().c_str());
  std::fflush(stderr);
  std::thread stopper([&] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    server.Stop();
  });
  if (a.open) OpenInBrowser(server.url());
  server.Run();
  // Run returns only after Stop: the stopper has already taken its signal.
  stopper.join();
  std::fprintf(stderr, "bouncecal: stopped\n");
}

}  // namespace

void RegisterServe(CLI::App& app) {
  auto args = std::make_shared<ServeArgs>();
  CLI::App* sub = app.add_subcommand(
      "serve", "a local web page to record, watch impacts live, calibrate and export");
  sub->add_option("--port", args->port, "TCP port (0: a free one)")->capture_default_str();
  sub->add_option("--host", args->host,
                  "address to listen on (default loopback: this machine only; another "
                  "address lets everyone on that network use the server)")
      ->capture_default_str();
  sub->add_flag("--open", args->open, "open the page in the desktop's browser");
  sub->add_option("--max-body-mb", args->max_body_mb, "largest upload, MB (larger: 413)")
      ->capture_default_str();
  sub->add_option("--jobs", args->jobs, "threads of one fit (default: the cores, at most 8)");
  sub->add_option("--idle-timeout", args->idle_timeout_s,
                  "close a connection silent for this long, s")
      ->capture_default_str();
  sub->callback([args]() { Run(*args); });
}

}  // namespace bouncecal::cli
