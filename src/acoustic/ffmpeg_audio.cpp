// Decoding through FFmpeg's libraries (libavformat, libavcodec, libswresample): the formats
// phones write (m4a/AAC from iPhone Voice Memos and most Android recorders, 3gp/AMR, opus in
// webm/ogg, ...) that libsndfile cannot read. See include/bouncecal/acoustic/audio.hpp.
//
// Built as its own module, libbouncecal_ffmpeg.so, which the library loads the first time a
// file needs it (src/acoustic/ffmpeg_module.cpp): FFmpeg pulls in 134 shared libraries, whose
// loading and relocation cost every process ~0.1 s of CPU when linked directly. The module's
// one entry point, bouncecal_ffmpeg_decode_v1, returns errors as a code and a message (no
// exception crosses the module boundary).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/channel_layout.h>
#include <libavutil/intreadwrite.h>
#include <libavutil/log.h>
#include <libswresample/swresample.h>
}

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

std::string AvError(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof buf);
  return buf;
}

struct FormatCloser {
  void operator()(AVFormatContext* f) const { avformat_close_input(&f); }
};
struct CodecCloser {
  void operator()(AVCodecContext* c) const { avcodec_free_context(&c); }
};
struct PacketFree {
  void operator()(AVPacket* p) const { av_packet_free(&p); }
};
struct FrameFree {
  void operator()(AVFrame* f) const { av_frame_free(&f); }
};
struct SwrFree {
  void operator()(SwrContext* s) const { swr_free(&s); }
};

// Decoded audio accumulates here; `skip_start` sums the priming samples the container told the
// decoder to drop (AV_PKT_DATA_SKIP_SAMPLES), which libavcodec trims itself.
struct Sink {
  std::vector<std::vector<float>>* channels;
  SwrContext* swr;
  std::vector<float*> planes;
  std::vector<std::vector<float>> buf;
  // What `swr` was set up for (the decoder's format when opened). MPEG audio may switch channel
  // count or sample format from one frame to the next (a fuzzed MPEG-1 Layer I file went stereo
  // -> mono); converting such a frame with this context read a missing input plane (SEGV).
  int in_format;
  int in_rate_hz;
  const std::string* path;
};

void Append(Sink* s, const AVFrame* frame) {
  const int nch = static_cast<int>(s->channels->size());
  if (frame->format != s->in_format || frame->ch_layout.nb_channels != nch ||
      frame->sample_rate != s->in_rate_hz) {
    const char* fmt = av_get_sample_fmt_name(static_cast<AVSampleFormat>(frame->format));
    throw Error(ErrorCode::kNotAudio,
                *s->path + ": the audio stream changes format after " +
                    std::to_string((*s->channels)[0].size()) + " frames (" + std::to_string(nch) +
                    " channels at " + std::to_string(s->in_rate_hz) + " Hz, then " +
                    std::to_string(frame->ch_layout.nb_channels) + " channels at " +
                    std::to_string(frame->sample_rate) + " Hz, " +
                    (fmt != nullptr ? fmt : "unknown") + " samples); not supported");
  }
  const int cap = swr_get_out_samples(s->swr, frame->nb_samples);
  s->buf.assign(static_cast<std::size_t>(nch),
                std::vector<float>(static_cast<std::size_t>(std::max(cap, 1))));
  s->planes.resize(static_cast<std::size_t>(nch));
  for (int c = 0; c < nch; ++c)
    s->planes[static_cast<std::size_t>(c)] = s->buf[static_cast<std::size_t>(c)].data();
  const int got = swr_convert(s->swr, reinterpret_cast<uint8_t**>(s->planes.data()), cap,
                              const_cast<const uint8_t**>(frame->extended_data), frame->nb_samples);
  if (got <= 0) return;
  for (int c = 0; c < nch; ++c) {
    auto& dst = (*s->channels)[static_cast<std::size_t>(c)];
    const auto& src = s->buf[static_cast<std::size_t>(c)];
    dst.insert(dst.end(), src.begin(), src.begin() + got);
  }
}

Audio Decode(const std::string& path) {
  av_log_set_level(AV_LOG_QUIET);  // our messages only
  AVFormatContext* raw = nullptr;
  int rc = avformat_open_input(&raw, path.c_str(), nullptr, nullptr);
  if (rc < 0)
    throw Error(ErrorCode::kNotAudio, path + ": FFmpeg cannot open it (" + AvError(rc) + ")");
  std::unique_ptr<AVFormatContext, FormatCloser> fmt(raw);
  if ((rc = avformat_find_stream_info(fmt.get(), nullptr)) < 0)
    throw Error(ErrorCode::kNotAudio, path + ": FFmpeg finds no streams (" + AvError(rc) + ")");
  const AVCodec* codec = nullptr;
  const int si = av_find_best_stream(fmt.get(), AVMEDIA_TYPE_AUDIO, -1, -1, &codec, 0);
  if (si < 0 || codec == nullptr)
    throw Error(ErrorCode::kNotAudio, path + ": no audio stream FFmpeg can decode");
  AVStream* st = fmt->streams[si];
  std::unique_ptr<AVCodecContext, CodecCloser> dec(avcodec_alloc_context3(codec));
  if (!dec || avcodec_parameters_to_context(dec.get(), st->codecpar) < 0 ||
      avcodec_open2(dec.get(), codec, nullptr) < 0)
    throw Error(ErrorCode::kNotAudio, path + ": cannot open the " + codec->name + " decoder");
  const int nch = dec->ch_layout.nb_channels;
  const int rate = dec->sample_rate;
  if (nch < 1) throw Error(ErrorCode::kNotAudio, path + ": the audio stream has no channels");
  if (rate < kMinSampleRateHz || rate > kMaxSampleRateHz)
    throw Error(ErrorCode::kNotAudio, path + ": unsupported sample rate " + std::to_string(rate) +
                                          " Hz (expected " + std::to_string(kMinSampleRateHz) +
                                          " to " + std::to_string(kMaxSampleRateHz) + " Hz)");
  SwrContext* swr_raw = nullptr;
  if (swr_alloc_set_opts2(&swr_raw, &dec->ch_layout, AV_SAMPLE_FMT_FLTP, rate, &dec->ch_layout,
                          dec->sample_fmt, rate, 0, nullptr) < 0 ||
      swr_init(swr_raw) < 0) {
    swr_free(&swr_raw);
    throw Error(ErrorCode::kNotAudio,
                path + ": cannot convert " + av_get_sample_fmt_name(dec->sample_fmt) + " samples");
  }
  std::unique_ptr<SwrContext, SwrFree> swr(swr_raw);

  Audio a;
  a.channels.assign(static_cast<std::size_t>(nch), {});
  Sink sink{&a.channels, swr.get(), {}, {}, dec->sample_fmt, rate, &path};
  std::unique_ptr<AVPacket, PacketFree> pkt(av_packet_alloc());
  std::unique_ptr<AVFrame, FrameFree> frame(av_frame_alloc());
  long long skipped = 0;
  bool corrupt = false;
  auto drain = [&]() {
    while ((rc = avcodec_receive_frame(dec.get(), frame.get())) >= 0) {
      Append(&sink, frame.get());
      av_frame_unref(frame.get());
    }
  };
  while ((rc = av_read_frame(fmt.get(), pkt.get())) >= 0) {
    if (pkt->stream_index == si) {
      std::size_t size = 0;
      const uint8_t* side = av_packet_get_side_data(pkt.get(), AV_PKT_DATA_SKIP_SAMPLES, &size);
      if (side && size >= 4) skipped += AV_RL32(side);
      if (avcodec_send_packet(dec.get(), pkt.get()) < 0) corrupt = true;
      drain();
    }
    av_packet_unref(pkt.get());
  }
  if (rc != AVERROR_EOF) corrupt = true;
  avcodec_send_packet(dec.get(), nullptr);
  drain();
  if (a.channels[0].empty())
    throw Error(ErrorCode::kNotAudio, path + ": FFmpeg decoded no audio frames" +
                                          std::string(corrupt ? " (damaged or truncated)" : ""));
  if (corrupt)
    throw Error(ErrorCode::kNotAudio, path + ": truncated or damaged (FFmpeg stopped after " +
                                          std::to_string(a.channels[0].size()) +
                                          " decoded frames)");

  a.info.path = path;
  a.info.sample_rate_hz = rate;
  a.info.channels = nch;
  a.info.frames = static_cast<std::int64_t>(a.channels[0].size());
  a.info.format = fmt->iformat && fmt->iformat->name ? fmt->iformat->name : "unknown";
  a.info.subtype = codec->name;
  a.info.decoder = "ffmpeg";
  const AVCodecDescriptor* desc = avcodec_descriptor_get(codec->id);
  a.info.lossy = desc != nullptr && (desc->props & AV_CODEC_PROP_LOSSY) != 0;
  // Priming samples: what the container told the decoder to drop (trimmed), else the encoder
  // delay the stream declares (libavcodec may not have trimmed it: reported, times keep it).
  a.info.codec_delay_samples = skipped > 0 ? skipped : st->codecpar->initial_padding;
  a.info.codec_delay_trimmed = skipped > 0;
  return a;
}

}  // namespace
}  // namespace bouncecal

extern "C" __attribute__((visibility("default"))) int bouncecal_ffmpeg_decode_v1(
    const char* path, bouncecal::Audio* out, int* exit_code, char* message,
    std::size_t message_size) {
  std::string why;
  try {
    *out = bouncecal::Decode(path);
    return 0;
  } catch (const bouncecal::Error& e) {
    *exit_code = e.exit_code();
    why = e.what();
  } catch (const std::exception& e) {
    *exit_code = static_cast<int>(bouncecal::ErrorCode::kInternal);
    why = std::string(path) + ": FFmpeg decoding: " + e.what();
  }
  std::snprintf(message, message_size, "%s", why.c_str());
  return 1;
}
