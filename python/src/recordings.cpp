// read_audio, detect, analyze, calibrate: the bindings that read recordings.
#include <string>

#include <pybind11/numpy.h>

#include "bindings.hpp"
#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal::python {
namespace {

// The waveform and what the decoder says about it: {"sample_rate_hz", "channels", "frames",
// "format", "codec", "decoder", "lossy", "samples": float32 array [channel, frame]}.
py::object ReadAudioBinding(const std::string& path) {
  Audio audio;
  {
    py::gil_scoped_release release;
    audio = ReadAudio(path);
  }
  const auto n_channels = static_cast<py::ssize_t>(audio.channels.size());
  const auto n_frames = static_cast<py::ssize_t>(audio.info.frames);
  py::array_t<float> samples({n_channels, n_frames});
  auto out = samples.mutable_unchecked<2>();
  for (py::ssize_t c = 0; c < n_channels; ++c) {
    const std::vector<float>& ch = audio.channels[static_cast<std::size_t>(c)];
    for (py::ssize_t f = 0; f < n_frames && f < static_cast<py::ssize_t>(ch.size()); ++f)
      out(c, f) = ch[static_cast<std::size_t>(f)];
  }
  py::dict d;
  d["file"] = path;
  d["sample_rate_hz"] = audio.info.sample_rate_hz;
  d["channels"] = audio.info.channels;
  d["frames"] = audio.info.frames;
  d["duration_s"] = audio.info.duration_s();
  d["format"] = audio.info.format;
  d["codec"] = audio.info.subtype;
  d["decoder"] = audio.info.decoder;
  d["lossy"] = audio.info.lossy;
  d["samples"] = samples;
  return d;
}

}  // namespace

void BindRecordings(py::module_& m) { m.def("read_audio", &ReadAudioBinding, py::arg("path")); }

}  // namespace bouncecal::python
