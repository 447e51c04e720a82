// `bouncecal serve` (src/serve): the API answers what the commands print, a live stream reports
// the impacts of the recording streamed to it, and bad requests are refused one by one without
// harming the server: 100 malformed requests, then a good one that succeeds. In-process servers
// on free ports (Server, port 0), and the program itself for Ctrl-C and --host.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <regex>
#include <string>
#include <thread>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/serve/server.hpp"
#include "json_schema.hpp"
#include "serve_client.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

using namespace testing_util;
using nlohmann::json;

const std::string kSrc = BOUNCECAL_SOURCE_DIR;
const std::string kFlac = kSrc + "/data/default_steel_copper.flac";
// The bundled recording's scene (data/default_steel_copper.toml) as parameters and as flags.
// (calibrate and report add the law).
const std::string kBall = "height=0.2&diameter=0.01&material=steel&contact_duration";
const std::string kBallFlags = " --height 0.2 --diameter 0.01 --material steel --contact-duration";
const std::string kLaw = "&law=hertz-viscoelastic";
const std::string kLawFlags = " --law hertz-viscoelastic";

const SchemaSet& Schemas() {
  static const SchemaSet set(kSrc + "/docs/schema");
  return set;
}
void ExpectValid(const json& j, const std::string& file) {
  const auto errors = Schemas().Validate(j, file);
  std::string all;
  for (const auto& e : errors) all += e + "\n";
  EXPECT_TRUE(errors.empty()) << file << ":\n" << all;
}

// An in-process server on a free port, run on a thread of its own.
class TestServer {
 public:
  explicit TestServer(serve::ServeOptions o = {}) {
    o.port = 0;
    server_ = std::make_unique<serve::Server>(o);
    thread_ = std::thread([this] { server_->Run(); });
  }
  ~TestServer() {
    server_->Stop();
    thread_.join();
  }
  int port() const { return server_->port(); }
  serve::Server& server() { return *server_; }

 private:
  std::unique_ptr<serve::Server> server_;
  std::thread thread_;
};

json WithoutVolatile(json j) {
  // What differs between two runs of the same analysis: the file's name and the fit's date.
  if (j.is_object()) {
    j.erase("file");
    j.erase("date_utc");
    for (auto& [k, v] : j.items()) v = WithoutVolatile(v);
  } else if (j.is_array()) {
    for (auto& v : j) v = WithoutVolatile(v);
  }
  return j;
}

json Cli(const std::string& args, int expect = 0) {
  const CommandResult r = RunCommand(BOUNCECAL_BINARY, args);
  EXPECT_EQ(r.exit_code, expect) << args << "\n" << r.err;
  return json::parse(r.out, nullptr, false);
}

TEST(ServeApi, AnalyzeUploadEqualsTheCommandsJson) {
  TestServer s;
  const std::string flac = Slurp(kFlac);
  const HttpReply raw = Post(s.port(), "/api/analyze?" + kBall + "&name=drop.flac", flac);
  ASSERT_EQ(raw.status, 200) << raw.body;
  const json got = raw.json();
  EXPECT_EQ(got["file"], "drop.flac");
  ExpectValid(got, "analysis.schema.json");
  const json cli = Cli("analyze " + kFlac + kBallFlags + " --json");
  EXPECT_EQ(WithoutVolatile(got), WithoutVolatile(cli));
  // The same as multipart/form-data, as a browser's form sends it.
  const std::string boundary = "----bouncecal-test";
  const std::string body = "--" + boundary +
                           "\r\nContent-Disposition: form-data; name=\"file\"; "
                           "filename=\"../../etc/drop.flac\"\r\nContent-Type: audio/flac\r\n\r\n" +
                           flac + "\r\n--" + boundary + "--\r\n";
  const HttpReply form =
      Post(s.port(), "/api/analyze?" + kBall, body, "multipart/form-data; boundary=" + boundary);
  ASSERT_EQ(form.status, 200) << form.body;
  EXPECT_EQ(form.json()["file"], "drop.flac") << "a name, never a path";
  EXPECT_EQ(WithoutVolatile(form.json()), WithoutVolatile(cli));
}

TEST(ServeApi, CalibrateExportAndReport) {
  TestServer s;
  const std::string flac = Slurp(kFlac);
  const HttpReply cal = Post(s.port(), "/api/calibrate?" + kBall + kLaw + "&name=drop.flac", flac);
  ASSERT_EQ(cal.status, 200) << cal.body;
  EXPECT_EQ(cal.exit_code, "0");
  const json params = cal.json();
  ExpectValid(params, "params.schema.json");
  const json cli = Cli("calibrate " + kFlac + kBallFlags + kLawFlags + " --json");
  EXPECT_EQ(WithoutVolatile(params), WithoutVolatile(cli));
  EXPECT_EQ(params["provenance"]["inputs"][0]["file"], "drop.flac");

  const HttpReply zip = Post(s.port(), "/api/export?to=lammps", cal.body, "application/json");
  ASSERT_EQ(zip.status, 200) << zip.body;
  EXPECT_EQ(zip.content_type, "application/zip");
  EXPECT_NE(zip.disposition.find("bounce_lammps.zip"), std::string::npos);
  ScratchDir dir("bc_serve");
  { std::ofstream(dir / "deck.zip", std::ios::binary) << zip.body; }
  // Python's zipfile reads it: the deck's files, run.sh executable.
  const CommandResult list =
      RunCommand("python3",
                 "-c \"import zipfile,sys; z=zipfile.ZipFile(sys.argv[1]); assert z.testzip() is "
                 "None; [print(i.filename, oct(i.external_attr >> 16)) for i in z.infolist()]\" " +
                     dir / "deck.zip");
  ASSERT_EQ(list.exit_code, 0) << list.err;
  EXPECT_NE(list.out.find("bounce_lammps/in.bounce"), std::string::npos) << list.out;
  EXPECT_TRUE(std::regex_search(list.out, std::regex("bounce_lammps/run.sh 0o1007[57][57]")))
      << list.out;

  const HttpReply report = Post(s.port(), "/api/report?" + kBall + kLaw, flac);
  ASSERT_EQ(report.status, 200) << report.body;
  EXPECT_NE(report.body.find("bouncecal.report/2"), std::string::npos);
  EXPECT_NE(report.disposition.find("report.html"), std::string::npos);
}

TEST(ServeApi, BodiesAboveTheCapAreRefusedWith413) {
  serve::ServeOptions o;
  o.max_body_bytes = 64 * 1024;
  TestServer s(o);
  const HttpReply r = Post(s.port(), "/api/analyze", std::string(100 * 1024, 'x'));
  EXPECT_EQ(r.status, 413);
  ExpectValid(r.json(), "error.schema.json");
  EXPECT_NE(r.json()["error"]["message"].get<std::string>().find("limit"), std::string::npos);
  // A chunked body is counted as it comes.
  const std::string chunked =
      "POST /api/analyze HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n" +
      std::string("10000\r\n") + std::string(0x10000, 'y') + "\r\n" + "10000\r\n" +
      std::string(0x10000, 'y') + "\r\n0\r\n\r\n";
  EXPECT_NE(Raw(s.port(), chunked).find("HTTP/1.1 413"), std::string::npos);
  EXPECT_EQ(Get(s.port(), "/api/sessions").status, 200) << "the server still answers";
}

// 100 malformed requests of every kind, then a good one: it succeeds, and no request left a
// file behind.
TEST(ServeApi, HundredMalformedRequestsThenAGoodOne) {
  serve::ServeOptions o;
  o.max_body_bytes = 4 << 20;
  TestServer s(o);
  const std::string flac = Slurp(kFlac);
  std::mt19937 rng(5);
  auto noise = [&](std::size_t n) {
    std::string b(n, '\0');
    for (char& c : b) c = static_cast<char>(rng() & 0xff);
    return b;
  };
  const std::string boundary = "xyz";
  const std::string truncated_form = "--" + boundary +
                                     "\r\nContent-Disposition: form-data; name=\"f\"; "
                                     "filename=\"a.flac\"\r\n\r\n" +
                                     flac.substr(0, 5000);
  int refused = 0;
  for (int k = 0; k < 100; ++k) {
    HttpReply r;
    switch (k % 10) {
      case 0:  // bad JSON as a parameter file
        r = Post(s.port(), "/api/export?to=lammps", "{\"schema\": \"bouncecal.params/2\", ",
                 "application/json");
        break;
      case 1:  // not audio
        r = Post(s.port(), "/api/analyze", noise(2000 + static_cast<std::size_t>(k)));
        break;
      case 2:  // a truncated multipart body
        r = Post(s.port(), "/api/analyze", truncated_form,
                 "multipart/form-data; boundary=" + boundary);
        break;
      case 3:  // over the cap
        r = Post(s.port(), "/api/analyze", std::string(5 << 20, 'a'));
        break;
      case 4:  // unknown routes
        r = Get(s.port(), "/api/nothing/" + std::to_string(k));
        break;
      case 5:  // paths out of the tree
        r = Get(s.port(), k % 20 == 5 ? "/../../etc/passwd" : "/api/takes/../../etc/passwd");
        break;
      case 6:  // a bad parameter
        r = Post(s.port(), "/api/analyze?height=abc", flac);
        break;
      case 7:  // a truncated audio file
        r = Post(s.port(), "/api/analyze", flac.substr(0, flac.size() / 3));
        break;
      case 8: {  // garbage instead of HTTP
        const std::string reply = Raw(s.port(), noise(300) + "\r\n\r\n");
        r.status = reply.rfind("HTTP/1.1 400", 0) == 0 ? 400 : (reply.empty() ? 0 : 1);
        break;
      }
      default:  // an unknown parameter, a wrong method, a take that does not exist
        r = k % 20 == 9 ? Post(s.port(), "/api/analyze?hieght=0.2", flac)
                        : Get(s.port(), "/api/takes/0123456789abcdef0123456789abcdef.flac");
        break;
    }
    EXPECT_GE(r.status, 400) << "request " << k << ": " << r.body;
    EXPECT_LT(r.status, 500) << "request " << k << ": " << r.body;
    if (r.status >= 400 && !r.body.empty()) ExpectValid(r.json(), "error.schema.json");
    refused += r.status >= 400 ? 1 : 0;
  }
  EXPECT_EQ(refused, 100);
  const HttpReply good = Post(s.port(), "/api/analyze?" + kBall, flac);
  ASSERT_EQ(good.status, 200) << good.body;
  EXPECT_EQ(good.json()["bounces"].size(), 74u);
  std::size_t left = 0;
  for (const auto& e : std::filesystem::directory_iterator(s.server().temp_dir()))
    left += e.path().filename().string().rfind("request-", 0) == 0 ? 1 : 0;
  EXPECT_EQ(left, 0u) << "every request's directory was removed";
}

// Streams `seconds` of the bundled recording (from `from_s`) in 2048-sample frames.
std::vector<json> Stream(LiveClient& c, double from_s, double seconds, bool stop = true) {
  const Audio& a = []() -> const Audio& {
    static const Audio x = ReadAudio(kFlac);
    return x;
  }();
  std::vector<json> out;
  EXPECT_TRUE(c.Text("{\"rate\": 48000}"));
  out.push_back(c.Next());
  const auto& x = a.channels[0];
  const auto i0 = static_cast<std::size_t>(from_s * 48000);
  const std::size_t i1 = std::min(x.size(), i0 + static_cast<std::size_t>(seconds * 48000));
  for (std::size_t i = i0; i < i1; i += 2048) {
    EXPECT_TRUE(c.Samples(x.data() + i, std::min<std::size_t>(2048, i1 - i)));
    while (c.Ready()) out.push_back(c.Next());
  }
  if (stop) {
    EXPECT_TRUE(c.Text("{\"stop\": true}"));
    for (json m = c.Next(); !m.is_null(); m = c.Next()) out.push_back(m);
  }
  return out;
}

TEST(ServeLive, StreamReportsTheImpactsAndTheTakesAnalysis) {
  TestServer s;
  LiveClient c(s.port(), "?" + kBall);
  ASSERT_TRUE(c.ok()) << c.error().message();
  const std::vector<json> messages = Stream(c, 0.0, 100.0);
  ASSERT_GE(messages.size(), 3u);
  EXPECT_EQ(messages.front()["type"], "started");
  int impacts_before_stop = 0;
  json analysis;
  for (const json& m : messages) {
    ExpectValid(m, "live.schema.json");
    if (m["type"] == "impact") ++impacts_before_stop;
    if (m["type"] == "analysis") analysis = m;
  }
  EXPECT_GE(impacts_before_stop, 60);
  ASSERT_TRUE(analysis.is_object());
  ASSERT_TRUE(analysis["analysis"].is_object()) << analysis.dump();
  EXPECT_EQ(analysis["analysis"]["bounces"].size(), 74u);
  // The take, downloaded, is the stream (24-bit FLAC of a 16-bit source: exact).
  const std::string url = analysis["take"]["url"];
  const HttpReply take = Get(s.port(), url);
  ASSERT_EQ(take.status, 200);
  EXPECT_EQ(take.content_type, "audio/flac");
  ScratchDir dir("bc_serve");
  { std::ofstream(dir / "take.flac", std::ios::binary) << take.body; }
  const json cli = Cli("analyze " + dir / "take.flac" + kBallFlags + " --json");
  EXPECT_EQ(WithoutVolatile(analysis["analysis"]), WithoutVolatile(cli));
  // The session is listed with its impacts; the take can be calibrated by its id.
  const json sessions = Get(s.port(), "/api/sessions").json();
  ASSERT_EQ(sessions.size(), 1u);
  ExpectValid(sessions[0], "live_session.schema.json");
  EXPECT_EQ(sessions[0]["state"], "finished");
  EXPECT_GE(sessions[0]["impacts"].size(), 63u);
  EXPECT_EQ(sessions[0]["samples"], analysis["take"]["frames"]);
  const HttpReply cal = Post(
      s.port(),
      "/api/calibrate?" + kBall + kLaw + "&take=" + analysis["take"]["id"].get<std::string>(), "");
  EXPECT_EQ(cal.status, 200) << cal.body;
}

// A malformed message closes its own stream with an error message; another stream, open at
// the same time, goes on and finishes.
TEST(ServeLive, MalformedMessagesCloseOnlyTheirSession) {
  TestServer s;
  LiveClient good(s.port());
  ASSERT_TRUE(good.Text("{\"rate\": 48000}"));
  EXPECT_EQ(good.Next()["type"], "started");
  struct Case {
    std::vector<std::pair<bool, std::string>> frames;  // (binary, bytes)
    std::string expect;
  };
  const float nan = std::nanf("");
  const std::vector<Case> cases = {
      {{{true, std::string(400, '\0')}}, "first message"},
      {{{false, "{\"rate\": 48000}"}, {true, std::string(7, '\0')}}, "whole number"},
      {{{false, "{\"rate\": 48000}"}, {true, std::string(reinterpret_cast<const char*>(&nan), 4)}},
       "NaN"},
      {{{false, "{\"rate\": 1000}"}}, "rate"},
      {{{false, "not json"}}, "{\"rate\": R}"},
      {{{false, "{\"rate\": 48000}"}, {false, "{\"stop\": false}"}}, "stop"},
      {{{false, "{\"rate\": 48000}"}, {true, std::string((1 << 20) + 4, '\0')}}, "at most"},
  };
  for (const Case& k : cases) {
    LiveClient bad(s.port());
    json last;
    for (const auto& [binary, bytes] : k.frames) {
      binary ? bad.Binary(bytes) : bad.Text(bytes);
      if (!binary && bytes.find("48000") != std::string::npos) bad.Next();  // started
    }
    last = bad.Next();
    ASSERT_TRUE(last.is_object()) << k.expect;
    EXPECT_EQ(last["type"], "error") << last.dump();
    ExpectValid(last, "live.schema.json");
    EXPECT_NE(last["error"]["message"].get<std::string>().find(k.expect), std::string::npos)
        << last.dump();
    EXPECT_TRUE(bad.Next().is_null()) << "closed after the error";
    EXPECT_EQ(bad.reason().code, websocket::close_code::policy_error);
  }
  // The good stream is unharmed.
  const Audio a = ReadAudio(kFlac);
  for (std::size_t i = 0; i < a.channels[0].size(); i += 4096)
    ASSERT_TRUE(good.Samples(a.channels[0].data() + i,
                             std::min<std::size_t>(4096, a.channels[0].size() - i)));
  ASSERT_TRUE(good.Text("{\"stop\": true}"));
  json analysis;
  for (json m = good.Next(); !m.is_null(); m = good.Next())
    if (m["type"] == "analysis") analysis = m;
  ASSERT_TRUE(analysis["analysis"].is_object()) << analysis.dump();
  EXPECT_EQ(analysis["analysis"]["bounces"].size(), 74u);
}

TEST(ServeLive, BadQueryIsRefusedBeforeTheUpgrade) {
  TestServer s;
  const std::string reply =
      Raw(s.port(),
          "GET /api/live?height=-3 HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n"
          "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
          "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n");
  EXPECT_EQ(reply.rfind("HTTP/1.1 400", 0), 0u) << reply;
  EXPECT_NE(reply.find("height"), std::string::npos) << reply;
}

TEST(ServeApi, IdleConnectionsAreClosed) {
  serve::ServeOptions o;
  o.idle_timeout_s = 0.5;
  TestServer s(o);
  const auto start = std::chrono::steady_clock::now();
  const std::string reply = Raw(s.port(), "GET / HTTP/1.1\r\n", /*close_write=*/false);
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(reply.empty()) << reply.substr(0, 200);
  EXPECT_LT(waited, 5.0) << "closed by the server, not by the client's 10 s";
}

TEST(ServeApi, PageIsSelfContained) {
  TestServer s;
  const HttpReply page = Get(s.port(), "/?autostart=1");
  ASSERT_EQ(page.status, 200);
  EXPECT_EQ(page.content_type, "text/html; charset=utf-8");
  const std::regex url(R"((https?|ftp|wss?):|//cdn|(src|href)\s*=\s*["']?//)", std::regex::icase);
  EXPECT_FALSE(std::regex_search(page.body, url));
  EXPECT_EQ(page.body.find("<script src"), std::string::npos);
  EXPECT_NE(page.body.find("getUserMedia"), std::string::npos);
  const json laws = Get(s.port(), "/api/laws").json();
  ExpectValid(laws, "laws.schema.json");
}

// ---- the program: Ctrl-C, --host ----

struct Spawned {
  pid_t pid = -1;
  int err_fd = -1;
};
Spawned SpawnServe(const std::string& args) {
  int fds[2];
  EXPECT_EQ(::pipe(fds), 0);
  Spawned s;
  s.pid = ::fork();
  if (s.pid == 0) {
    ::dup2(fds[1], 2);
    ::close(fds[0]);
    ::execl("/bin/sh", "sh", "-c",
            (std::string("exec ") + BOUNCECAL_BINARY + " serve " + args).c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(fds[1]);
  s.err_fd = fds[0];
  return s;
}
// Reads stderr until `pattern` matches (or 20 s).
std::string ReadUntil(int fd, const std::regex& pattern) {
  std::string err;
  char buf[512];
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!std::regex_search(err, pattern) && std::chrono::steady_clock::now() < until) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n <= 0) break;
    err.append(buf, static_cast<std::size_t>(n));
  }
  return err;
}

TEST(ServeProgram, CtrlCStopsItCleanly) {
  Spawned p = SpawnServe("--port 0");
  const std::string err = ReadUntil(p.err_fd, std::regex(R"(serving http://127\.0\.0\.1:(\d+)/)"));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(err, m, std::regex(R"(127\.0\.0\.1:(\d+)/)"))) << err;
  const int port = std::stoi(m[1]);
  EXPECT_EQ(Get(port, "/").status, 200);
  LiveClient open(port);  // a stream in progress
  ASSERT_TRUE(open.Text("{\"rate\": 48000}"));
  EXPECT_EQ(open.Next()["type"], "started");
  ::kill(p.pid, SIGINT);
  int status = 0;
  ::waitpid(p.pid, &status, 0);
  const std::string rest = ReadUntil(p.err_fd, std::regex("stopped"));
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  EXPECT_NE(rest.find("stopped"), std::string::npos) << rest;
  ::close(p.err_fd);
}

TEST(ServeProgram, HostOtherThanLoopbackWarns) {
  Spawned p = SpawnServe("--port 0 --host 0.0.0.0");
  const std::string err = ReadUntil(p.err_fd, std::regex("serving"));
  EXPECT_NE(err.find("warning [serve_network]"), std::string::npos) << err;
  EXPECT_NE(err.find("anyone on that network"), std::string::npos) << err;
  ::kill(p.pid, SIGTERM);
  int status = 0;
  ::waitpid(p.pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  ::close(p.err_fd);
  const CommandResult busy = RunCommand(BOUNCECAL_BINARY, "serve --host 192.0.2.1 --port 0");
  EXPECT_EQ(busy.exit_code, 2) << busy.err;  // not an address of this machine
  EXPECT_NE(busy.err.find("192.0.2.1"), std::string::npos) << busy.err;
}

}  // namespace
}  // namespace bouncecal
