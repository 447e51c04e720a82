// Audio already in memory (NumPy arrays: sounddevice, a notebook, a DAQ) and live streams:
// detect/analyze on an array with its rate, and the Listener (acoustic/live.hpp) with the
// messages of io/live_json.hpp. Results are the CLI's JSON as for files: an array named "array"
// (or name=...) gives what `detect`/`analyze` give for a file holding the same samples.
#include <memory>
#include <optional>
#include <string>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/audio_writer.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/io/analysis_document.hpp"
#include "bouncecal/io/live_json.hpp"
#include "bouncecal/io/schema.hpp"

namespace bouncecal::python {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

Audio AudioFromArray(const FloatArray& samples, double rate_hz, const std::string& name) {
  if (samples.ndim() != 1 && samples.ndim() != 2)
    throw Error(ErrorCode::kUsage, name + ": expected a 1-D array (mono) or 2-D [channel, frame]");
  if (!(rate_hz >= kMinSampleRateHz && rate_hz <= kMaxSampleRateHz) ||
      rate_hz != static_cast<double>(static_cast<long>(rate_hz)))
    throw Error(ErrorCode::kUsage, name + ": rate " + std::to_string(rate_hz) +
                                       " Hz: expected a whole number of Hz in [" +
                                       std::to_string(kMinSampleRateHz) + ", " +
                                       std::to_string(kMaxSampleRateHz) + "]");
  const py::ssize_t channels = samples.ndim() == 1 ? 1 : samples.shape(0);
  const py::ssize_t frames = samples.ndim() == 1 ? samples.shape(0) : samples.shape(1);
  if (channels < 1 || channels > 64 || frames < 1)
    throw Error(ErrorCode::kNotAudio, name + ": " + std::to_string(channels) + " channel(s) of " +
                                          std::to_string(frames) + " frames");
  Audio a;
  a.info.path = name;
  a.info.sample_rate_hz = rate_hz;
  a.info.channels = static_cast<int>(channels);
  a.info.frames = frames;
  a.info.format = "array";
  a.info.subtype = "FLOAT";
  a.info.decoder = "numpy";
  const float* data = samples.data();
  for (py::ssize_t c = 0; c < channels; ++c) {
    const float* x = data + c * frames;
    for (py::ssize_t i = 0; i < frames; ++i)
      if (!(std::fabs(x[i]) <= kMaxSampleMagnitude))
        throw Error(ErrorCode::kBadSamples,
                    BadSampleMessage(name, x[i], static_cast<std::size_t>(c), i, rate_hz));
    a.channels.emplace_back(x, x + frames);
    a.clipping.push_back(AnalyzeClipping(a.channels.back(), static_cast<int>(c)));
  }
  return a;
}

namespace {

// `bouncecal detect FILE --json` on the array.
py::object DetectArray(const FloatArray& samples, double rate_hz, const py::dict& options) {
  Options o(options);
  const std::string name = o.TakeString("name").value_or("array");
  const DropInputOptions flags = TakeDropInputOptions(o);
  o.Finish("detect");
  const Audio audio = AudioFromArray(samples, rate_hz, name);
  py::gil_scoped_release release;
  const LoadedRecording l = LoadRecording(name, &audio, "", flags);
  const nlohmann::json j = DetectionJson(name, l.result, {.chosen = l.chosen});
  py::gil_scoped_acquire acquire;
  return ToPython(j);
}

// `bouncecal analyze FILE --json` on the array.
py::object AnalyzeArray(const FloatArray& samples, double rate_hz, const py::dict& options) {
  Options o(options);
  const std::string name = o.TakeString("name").value_or("array");
  const DropInputOptions flags = TakeDropInputOptions(o);
  const SceneOverrides scene = TakeSceneOverrides(o, /*with_law=*/false);
  const std::optional<double> contact_time_s = o.TakeDouble("contact_time");
  o.Finish("analyze");
  GivenScene gs = ResolveGivenScene(scene);
  const AnalysisOptions aopt = AnalyzeOptionsFor(&gs, contact_time_s);
  const Audio audio = AudioFromArray(samples, rate_hz, name);
  py::gil_scoped_release release;
  const LoadedRecording l = LoadRecording(name, &audio, "", flags);
  const std::vector<nlohmann::json> docs = AnalysisDocuments(name, l, gs, aopt);
  const nlohmann::json j = docs.size() == 1 ? docs.front() : nlohmann::json(docs);
  py::gil_scoped_acquire acquire;
  return ToPython(j);
}

// A live stream in Python: feed() -> the messages (dicts) of what became final, finish() -> the
// whole take's analysis. The take is kept in memory (4 bytes a sample), or written to `take`.
class Listener {
 public:
  Listener(double rate_hz, const py::dict& options) {
    Options o(options);
    name_ = o.TakeString("name").value_or("stream");
    const SceneOverrides scene = TakeSceneOverrides(o, /*with_law=*/false);
    LiveOptions lo;
    if (auto v = o.TakeDouble("min_snr_db")) lo.detect.min_snr_db = *v;
    const std::string take = o.TakeString("take").value_or("");
    const bool force = o.TakeFlag("force");
    o.Finish("Listener");
    gs_ = ResolveGivenScene(scene);
    analysis_ = AnalyzeOptionsFor(&gs_, std::nullopt);
    drops_.detect.min_snr_db = lo.detect.min_snr_db;
    live_ = std::make_unique<LiveDetector>(rate_hz, lo, name_);
    if (!take.empty()) {
      take_path_ = take;
      writer_ =
          std::make_unique<AudioWriter>(take, rate_hz, 1, AudioWriteOptions{.subtype = "PCM_24"},
                                        WriteOptions{.force = force, .inputs = {}});
    }
  }

  py::list Feed(const FloatArray& samples) {
    if (samples.ndim() != 1)
      throw Error(ErrorCode::kUsage, name_ + ": feed() takes a 1-D array of mono samples");
    const float* x = samples.data();
    const auto n = static_cast<std::size_t>(samples.shape(0));
    std::vector<nlohmann::json> messages;
    {
      py::gil_scoped_release release;
      const LiveUpdate u = live_->Feed(x, n);
      if (writer_) {
        writer_->Write(x, n);
      } else {
        memory_.insert(memory_.end(), x, x + n);
      }
      messages = LiveUpdateJson(u, *live_, {gs_.scene, analysis_});
    }
    py::list out;
    for (const nlohmann::json& m : messages) out.append(ToPython(m));
    return out;
  }

  // The last messages, then the analysis of the whole take (what `analyze TAKE --json` gives).
  py::object Finish() {
    if (live_->finished()) throw Error(ErrorCode::kUsage, name_ + ": finish() was called already");
    nlohmann::json analysis;
    {
      py::gil_scoped_release release;
      last_ = LiveUpdateJson(live_->Finish(), *live_, {gs_.scene, analysis_});
      LoadedRecording l;
      if (writer_) {
        writer_->Commit();
        l = LoadRecording(take_path_, nullptr, "", drops_);
      } else {
        Audio a;
        a.info.path = name_;
        a.info.sample_rate_hz = live_->rate_hz();
        a.info.channels = 1;
        a.info.frames = static_cast<std::int64_t>(memory_.size());
        a.info.format = "stream";
        a.info.subtype = "FLOAT";
        if (memory_.empty()) throw Error(ErrorCode::kNotAudio, name_ + ": no samples were fed");
        a.channels.push_back(std::move(memory_));
        a.clipping.push_back(AnalyzeClipping(a.channels[0], 0));
        l = LoadRecording(name_, &a, "", drops_);
      }
      analysis = AnalysisDocuments(writer_ ? take_path_ : name_, l, gs_, analysis_).front();
    }
    return ToPython(analysis);
  }

  py::list Impacts() const {
    py::list out;
    for (const LiveImpact& i : live_->Impacts()) out.append(ToPython(LiveImpactJson(i)));
    return out;
  }
  py::list LastMessages() const {
    py::list out;
    for (const nlohmann::json& m : last_) out.append(ToPython(m));
    return out;
  }
  double Rate() const { return live_->rate_hz(); }
  std::int64_t Frames() const { return live_->frames(); }

 private:
  std::string name_;
  GivenScene gs_;
  AnalysisOptions analysis_;
  DropInputOptions drops_;
  std::unique_ptr<LiveDetector> live_;
  std::unique_ptr<AudioWriter> writer_;
  std::string take_path_;
  std::vector<float> memory_;
  std::vector<nlohmann::json> last_;
};

}  // namespace

void BindLive(py::module_& m) {
  m.def("detect_array", &DetectArray, py::arg("samples"), py::arg("rate"), py::arg("options"));
  m.def("analyze_array", &AnalyzeArray, py::arg("samples"), py::arg("rate"), py::arg("options"));
  py::class_<Listener>(m, "Listener")
      .def(py::init<double, const py::dict&>(), py::arg("rate"), py::arg("options"))
      .def("feed", &Listener::Feed, py::arg("samples"))
      .def("finish", &Listener::Finish)
      .def_property_readonly("impacts", &Listener::Impacts)
      .def_property_readonly("last_messages", &Listener::LastMessages)
      .def_property_readonly("rate", &Listener::Rate)
      .def_property_readonly("frames", &Listener::Frames);
}

}  // namespace bouncecal::python
