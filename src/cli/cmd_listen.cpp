// `bouncecal listen [FILE|-]`: a recording as it arrives, each impact printed as soon as it is
// final (acoustic/live.hpp), the whole take's analysis when the stream ends (EOF or Ctrl-C).
//
//   arecord -f S16_LE -r 48000 -c 1 -t wav - | bouncecal listen -
//   sox -d -t raw -b 16 -e signed -r 48000 -c 1 - | bouncecal listen - --rate 48000
//   bouncecal listen drop.flac --json --height 0.2        # a file, as if it were live
//
// Text: one line per final impact (with the previous bounce's e once this impact closed its
// flight), one per revised sequence, then the whole take's per-bounce table. --json: one
// bouncecal.live/1 message per line (impact, revised, warning), the last one the analysis
// message (its "analysis" is what `analyze TAKE --json` prints). The stream is kept as a take
// (--take FILE.flac keeps it; by default a temporary file, removed at the end) and analysed
// whole at the end, so the final numbers are the batch detector's.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>

#include "bouncecal/acoustic/audio_writer.hpp"
#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/analysis_document.hpp"
#include "bouncecal/io/live_json.hpp"
#include "bouncecal/io/schema.hpp"
#include "commands.hpp"
#include "output.hpp"
#include "scene_flags.hpp"
#include "stream_input.hpp"

namespace bouncecal::cli {
namespace {

struct ListenArgs {
  std::string input = "-";
  bool json = false;
  RawFormat raw;
  std::string channel = "mix";
  SceneFlags scene;
  std::optional<double> min_snr_db;
  std::string take;
  bool force = false;
};

volatile std::sig_atomic_t g_interrupted = 0;
void OnInterrupt(int) { g_interrupted = 1; }

// Ctrl-C ends the stream (the analysis still comes); a second one ends the program.
void CatchInterrupt() {
  struct sigaction sa {};
  sa.sa_handler = OnInterrupt;
  sa.sa_flags = SA_RESETHAND;  // no SA_RESTART: a blocked read returns EINTR
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
}

// Where the samples come from: a stream (stdin, a FIFO) or a file read block by block.
struct Source {
  std::string name;
  double rate_hz = 0.0;
  int channels = 1;
  std::string description;
  bool stream = true;
  std::function<std::size_t(std::size_t, std::vector<float>*)> read;  // interleaved frames
  std::unique_ptr<StreamInput> input;
  std::unique_ptr<AudioReader> reader;
  int fd = -1;
  ~Source() {
    if (fd > 0) ::close(fd);
  }
};

std::unique_ptr<Source> OpenSource(const ListenArgs& a) {
  auto s = std::make_unique<Source>();
  s->name = a.input == "-" ? "stdin" : a.input;
  struct stat st {};
  if (a.input != "-" && ::stat(a.input.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
    s->stream = false;
    s->reader = std::make_unique<AudioReader>(a.input);
    s->rate_hz = s->reader->info().sample_rate_hz;
    s->channels = s->reader->info().channels;
    s->description = s->reader->info().format + " " + s->reader->info().subtype;
    AudioReader* r = s->reader.get();
    s->read = [r, ch = s->channels](std::size_t frames, std::vector<float>* out) {
      std::vector<std::vector<float>> block;
      const auto n = static_cast<std::size_t>(r->Read(static_cast<std::int64_t>(frames), &block));
      for (std::size_t i = 0; i < n; ++i)
        for (int c = 0; c < ch; ++c) out->push_back(block[static_cast<std::size_t>(c)][i]);
      return n;
    };
    return s;
  }
  if (a.input != "-") {
    s->fd = ::open(a.input.c_str(), O_RDONLY | O_CLOEXEC);
    if (s->fd < 0) throw Error(ErrorCode::kInputMissing, a.input + ": cannot be opened");
  }
  s->input = std::make_unique<StreamInput>(a.input == "-" ? STDIN_FILENO : s->fd, s->name, a.raw);
  s->rate_hz = s->input->rate_hz();
  s->channels = s->input->channels();
  s->description = s->input->description();
  StreamInput* in = s->input.get();
  s->read = [in](std::size_t frames, std::vector<float>* out) { return in->Read(frames, out); };
  return s;
}

// The listened-to signal of interleaved frames: one channel, or the mix.
std::vector<float> Mono(const std::vector<float>& x, int channels, int channel) {
  const auto nch = static_cast<std::size_t>(channels);
  std::vector<float> out(x.size() / nch);
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (channel >= 0) {
      out[i] = x[i * nch + static_cast<std::size_t>(channel)];
    } else {
      float sum = 0.0f;
      for (std::size_t c = 0; c < nch; ++c) sum += x[i * nch + c];
      out[i] = sum / static_cast<float>(nch);
    }
  }
  return out;
}

std::string Fixed(const nlohmann::json& v, const char* fmt, double scale = 1.0) {
  if (!v.is_number()) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v.get<double>() * scale);
  return buf;
}

void PrintMessage(const nlohmann::json& m, bool json) {
  if (json) {
    std::cout << DumpJson(m) << "\n" << std::flush;
    return;
  }
  const std::string type = m["type"];
  if (type == "impact") {
    const nlohmann::json& i = m["impact"];
    std::cout << "impact  sequence " << i["sequence"] << "  #" << i["index"]
              << "  t = " << Fixed(i["time_s"], "%.6f") << " s +- "
              << Fixed(i["time_sigma_s"], "%.2f", 1e6) << " us";
    const nlohmann::json& b = m["bounce"];
    if (b.is_object()) {
      std::cout << "  interval " << Fixed(b["interval_s"], "%.6f") << " s";
      if (b["e"].is_number())
        std::cout << "  e[" << b["index"] << "] = " << Fixed(b["e"], "%.5f") << " +- "
                  << Fixed(b["e_sigma"], "%.6f");
    }
    std::cout << "\n" << std::flush;
  } else if (type == "revised") {
    std::cout << "revised sequence " << m["sequence"] << " (" << m["reason"].get<std::string>()
              << "): " << m["impacts"].size() << " final impacts\n"
              << std::flush;
  } else if (type == "warning") {
    const nlohmann::json& w = m["warning"];
    PrintWarnings({{w["code"], w["message"], -1, w["hint"]}});
  }
}

// The whole take's analysis as text: its per-bounce table.
void PrintAnalysis(const nlohmann::json& a) {
  std::cout << "\nanalysis of the whole take (as `bouncecal analyze`): " << a["bounces"].size()
            << " impacts in the main sequence\n";
  std::printf("%4s %11s %8s %11s  %s\n", "k", "time_s", "sigma_us", "interval_s", "e");
  for (const nlohmann::json& b : a["bounces"]) {
    std::printf(
        "%4d %11s %8s %11s  %s\n", b["index"].get<int>(), Fixed(b["time_s"], "%.6f").c_str(),
        Fixed(b["time_sigma_s"], "%.2f", 1e6).c_str(), Fixed(b["interval_s"], "%.6f").c_str(),
        b["e"].is_number() ? (Fixed(b["e"], "%.5f") + " +- " + Fixed(b["e_sigma"], "%.6f")).c_str()
                           : "-");
  }
  std::fflush(stdout);
}

// A temporary directory for the take, removed at the end.
struct TempTake {
  std::string dir, path;
  TempTake() {
    std::string tmpl =
        (std::filesystem::temp_directory_path() / "bouncecal-listen-XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw Error(ErrorCode::kOutput, "cannot create a temporary directory for the take");
    dir = tmpl;
    path = dir + "/take.flac";
  }
  ~TempTake() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
};

void Run(const ListenArgs& a) {
  GivenScene gs = ResolveGivenScene(a.scene);
  const AnalysisOptions aopt = AnalyzeOptionsFor(&gs, std::nullopt);
  LiveOptions lo;
  if (a.min_snr_db) lo.detect.min_snr_db = *a.min_snr_db;
  DropInputOptions drops;
  drops.detect.min_snr_db = lo.detect.min_snr_db;
  drops.detect.channel = ParseChannelSelection(a.channel == "mix" ? "mix" : a.channel);
  if (drops.detect.channel.kind == ChannelSelection::Kind::kAuto)
    throw Error(ErrorCode::kUsage, "--channel auto: a live stream needs one signal (N or mix)");
  std::string why;
  if (!lo.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  if (!a.take.empty()) CheckOutputPath(a.take, {.force = a.force, .inputs = {a.input}});
  CatchInterrupt();
  std::unique_ptr<Source> src = OpenSource(a);
  const int channel =
      drops.detect.channel.kind == ChannelSelection::Kind::kIndex ? drops.detect.channel.index : -1;
  if (channel >= src->channels)
    throw Error(ErrorCode::kUsage, "--channel " + a.channel + ": " + src->name + " has " +
                                       std::to_string(src->channels) + " channel(s) (0-based)");
  // A mono take is analysed as `analyze TAKE` does (channel 0, not "the mix" of one channel).
  if (src->channels == 1) drops.detect.channel = ChannelSelection{};
  std::fprintf(stderr, "bouncecal: listening to %s: %s, %.0f Hz, %d channel(s)%s\n",
               src->name.c_str(), src->description.c_str(), src->rate_hz, src->channels,
               src->stream ? " (Ctrl-C or the end of the stream ends the take)" : "");
  std::optional<TempTake> temp;
  std::string take_path = a.take;
  if (take_path.empty() && src->stream) take_path = (temp.emplace()).path;
  std::unique_ptr<AudioWriter> take;
  if (!take_path.empty())
    take = std::make_unique<AudioWriter>(take_path, src->rate_hz, src->channels,
                                         AudioWriteOptions{.subtype = "PCM_24"},
                                         WriteOptions{.force = a.force, .inputs = {a.input}});
  LiveDetector live(src->rate_hz, lo, src->name);
  const LiveJsonOptions jo{gs.scene, aopt};
  // 20 ms at a time: a stream's samples are passed on as soon as they come.
  const auto block = static_cast<std::size_t>(std::max(1.0, 0.02 * src->rate_hz));
  std::vector<float> x;
  while (!g_interrupted) {
    x.clear();
    const std::size_t n = src->read(block, &x);
    if (n == 0) break;
    if (take) take->Write(x.data(), n);
    for (const nlohmann::json& m :
         LiveUpdateJson(live.Feed(Mono(x, src->channels, channel)), live, jo))
      PrintMessage(m, a.json);
  }
  for (const nlohmann::json& m : LiveUpdateJson(live.Finish(), live, jo)) PrintMessage(m, a.json);
  if (take) take->Commit();
  const std::string analysed = take ? take_path : a.input;
  nlohmann::json analysis = nullptr, error = nullptr, take_json = nullptr;
  std::optional<Error> failed;
  try {
    const LoadedRecording l = LoadRecording(analysed, nullptr, "", drops);
    analysis = AnalysisDocuments(a.take.empty() && src->stream ? src->name : analysed, l, gs, aopt)
                   .front();
  } catch (const Error& e) {
    std::string m = e.what();
    if (temp)
      for (std::size_t at; (at = m.find(temp->path)) != std::string::npos;)
        m.replace(at, temp->path.size(), src->name);
    failed = Error(e.code(), m);
    error = ErrorJson(e.code(), m);
  }
  if (!a.take.empty()) {
    take_json = {{"id", nullptr},
                 {"url", a.take},
                 {"frames", live.frames()},
                 {"duration_s", static_cast<double>(live.frames()) / src->rate_hz},
                 {"sample_rate_hz", src->rate_hz}};
  }
  if (a.json) {
    PrintMessage(LiveAnalysisMessageJson(analysis, error, take_json), true);
  } else if (analysis.is_object()) {
    PrintAnalysis(analysis);
  }
  if (failed) throw *failed;
}

}  // namespace

void RegisterListen(CLI::App& app) {
  auto args = std::make_shared<ListenArgs>();
  CLI::App* sub = app.add_subcommand(
      "listen", "print each impact of a live stream (WAV or raw PCM on stdin) as it happens");
  sub->add_option("FILE", args->input,
                  "- (standard input: WAV, or raw PCM with --rate), a FIFO, or a recording")
      ->capture_default_str();
  sub->add_flag("--json", args->json, "one JSON message per line (bouncecal.live/1)");
  sub->add_option("--rate", args->raw.rate_hz, "raw PCM: sample rate, Hz");
  sub->add_option("--format", args->raw.encoding, "raw PCM: s16le, s24le, s32le, f32le or u8")
      ->capture_default_str();
  sub->add_option("--channels", args->raw.channels, "raw PCM: channels")->capture_default_str();
  sub->add_option("--channel", args->channel, "which channel to listen to: N (0-based) or mix")
      ->capture_default_str();
  sub->add_option("--min-snr-db", args->min_snr_db,
                  "remove sequence members below this local SNR (dB; default: no cut)");
  AddOutputOption(sub, "--take", &args->take, "keep the stream as this file (.flac or .wav)");
  sub->add_flag("--force", args->force, "replace an existing --take file");
  AddSceneFlags(sub, &args->scene, /*with_law=*/false);
  sub->callback([args]() { Run(*args); });
}

}  // namespace bouncecal::cli
