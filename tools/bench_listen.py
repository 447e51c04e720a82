#!/usr/bin/env python3
"""bench_listen — how soon `bouncecal listen` prints an impact, and what a live stream costs it.

    python3 tools/bench_listen.py                       # the bundled drop, then three in a row
    python3 tools/bench_listen.py --takes 5 --period 2048 --bouncecal build/bouncecal

A recording is written into `bouncecal listen - --json` as `arecord -f S16_LE -c 1 -t wav -`
writes one: a WAV header whose lengths are placeholders, then 16-bit mono PCM in periods of
--period frames (1024: 21 ms at 48 kHz), each written when the real-time clock reaches its
last sample (a paced pipe: the microphone's sound reaches the program no sooner than it was
made). Each `impact` line is timestamped as it arrives on the program's standard output; its
latency is that time less the moment the period holding the impact's sample was written: the
time from the impact's sound being available to the program to its line being printed (the
settle time, the wait for the next detection run, the run itself). A drop's first two impacts
wait for its third (three impacts make a bounce sequence): their latency is a column of its own
(the first flight of the bundled drop lasts 0.37 s). Impacts printed after the end of the stream
(the last ones, made final by it) are counted apart and not in the latency.
The CPU share is the program's user + system time (/proc/PID/stat) over the stream, read as the
last period is written, per second of audio: the share of one core a live stream takes. Then the
end of the stream, and the time to the whole take's analysis (the batch detector's). Prints one
Markdown table; the machine's load average is printed with it (the machine may be shared).

The recordings: the bundled one (data/default_steel_copper.flac, 9.2 s at 48 kHz: one drop of
~70 impacts), and the same three times in a row (three drops, 28 s); each stream ends with 2 s of
digital silence, so that the last drop's last impacts are printed while the stream runs.
"""
import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RATE = 48000


def decode(path, loops, pad_s):
    """16-bit mono PCM at RATE of `path` played `loops` times, then pad_s of silence."""
    pcm = subprocess.run(
        ["ffmpeg", "-loglevel", "error", "-stream_loop", str(loops - 1), "-i", path,
         "-ar", str(RATE), "-ac", "1", "-f", "s16le", "-"],
        check=True, capture_output=True).stdout
    return pcm + bytes(2 * int(pad_s * RATE))


def wav_header():
    """A WAV header as arecord writes to a pipe: the RIFF and data lengths unknown."""
    fmt = struct.pack("<HHIIHH", 1, 1, RATE, 2 * RATE, 2, 16)
    return (b"RIFF" + struct.pack("<I", 0xFFFFFFFF) + b"WAVE" + b"fmt " +
            struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", 0xFFFFFFFF))


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def take(bouncecal, pcm, period):
    """One paced stream: per impact printed while it ran, its latency (s); and the totals."""
    proc = subprocess.Popen([bouncecal, "listen", "-", "--json"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    lines = []  # (arrival time, message)

    def read():
        for line in proc.stdout:
            lines.append((time.monotonic(), json.loads(line)))

    reader = threading.Thread(target=read)
    reader.start()
    proc.stdin.write(wav_header())
    proc.stdin.flush()
    frames = len(pcm) // 2
    written = []  # the time each period was written
    cpu0 = cpu_s(proc.pid)
    t0 = time.monotonic()
    for at in range(0, frames, period):
        n = min(period, frames - at)
        delay = t0 + (at + n) / RATE - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        proc.stdin.write(pcm[2 * at:2 * (at + n)])
        proc.stdin.flush()
        written.append(time.monotonic())
    end = time.monotonic()
    cpu = cpu_s(proc.pid) - cpu0
    proc.stdin.close()
    reader.join()
    stderr = proc.stderr.read().decode()
    if proc.wait() != 0:
        sys.exit(f"bouncecal listen exited with {proc.returncode}: {stderr}")
    latency, first, after_end, revised = [], [], 0, 0
    analysis_s = None
    for arrived, m in lines:
        if m["type"] == "revised":
            revised += 1
        elif m["type"] == "analysis":
            analysis_s = arrived - end
        elif m["type"] == "impact":
            if arrived > end:
                after_end += 1
                continue
            k = min(len(written) - 1, int(m["impact"]["time_s"] * RATE) // period)
            (latency if m["impact"]["index"] >= 2 else first).append(arrived - written[k])
    return {"latency": latency, "first": first, "after_end": after_end, "revised": revised,
            "cpu_share": cpu / (frames / RATE), "analysis_s": analysis_s, "audio_s": frames / RATE,
            "late_writes": sum(1 for k, w in enumerate(written)
                               if w - (t0 + min(frames, (k + 1) * period) / RATE) > 0.01)}


def quantile(v, p):
    s = sorted(v)
    return s[min(len(s) - 1, int(p * len(s)))]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bouncecal", default=os.path.join(ROOT, "build", "bouncecal"))
    ap.add_argument("--takes", type=int, default=3, help="streams per recording")
    ap.add_argument("--period", type=int, default=1024, help="frames per write")
    a = ap.parse_args()
    flac = os.path.join(ROOT, "data", "default_steel_copper.flac")
    print(f"machine: {os.cpu_count()} cores, load average "
          f"{' '.join(f'{v:.1f}' for v in os.getloadavg())}; writes of {a.period} frames "
          f"({1e3 * a.period / RATE:.0f} ms) at 48 kHz, paced in real time\n")
    print("| recording | audio | takes | impacts printed while streaming (per take) | after the "
          "end | revisions | latency median | p90 | max | first two of a drop: median | CPU per s of audio | end → analysis |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, loops in (("bundled drop", 1), ("bundled drop x 3", 3)):
        pcm = decode(flac, loops, 2.0)
        runs = [take(a.bouncecal, pcm, a.period) for _ in range(a.takes)]
        lat = [x for r in runs for x in r["latency"]]
        first = [x for r in runs for x in r["first"]]
        late = sum(r["late_writes"] for r in runs)
        print(f"| {name} | {runs[0]['audio_s']:.1f} s | {len(runs)} | "
              f"{', '.join(str(len(r['latency']) + len(r['first'])) for r in runs)} | "
              f"{', '.join(str(r['after_end']) for r in runs)} | "
              f"{', '.join(str(r['revised']) for r in runs)} | "
              f"{1e3 * statistics.median(lat):.0f} ms | {1e3 * quantile(lat, 0.9):.0f} ms | "
              f"{1e3 * max(lat):.0f} ms | {1e3 * statistics.median(first):.0f} ms | "
              f"{', '.join('%.1f %%' % (100 * r['cpu_share']) for r in runs)} | "
              f"{', '.join('%.2f s' % r['analysis_s'] for r in runs)} |")
        if late:
            print(f"({late} periods were written more than 10 ms late: the machine was busy)")


if __name__ == "__main__":
    main()
