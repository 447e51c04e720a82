#!/usr/bin/env python3
"""bad_inputs — the bad-input corpus (issue 14): every kind of bad input a user can give, run
through the real CLI, with its exit code and message.

    python3 tools/bad_inputs.py --bouncecal build/bouncecal              # table + checks
    python3 tools/bad_inputs.py --bouncecal build/bouncecal --markdown   # the documented table only
    python3 tools/bad_inputs.py --bouncecal build/bouncecal --readme docs/reliability.md [--update]
                                    # also check (rewrite) the copy of the table in docs/reliability.md

Builds every input in a temporary directory (audio with `bouncecal synth` or Python's
`wave`/`struct`; the bundled data/default_steel_copper.flac and .toml, copied, as the good
recording and scene), runs each command in a fresh copy of that directory with relative file
names as a user would, and prints one Markdown row per case: the input, the command, the exit
code and the first line of stderr. Each case is checked, and the script exits 1 if any check
fails:
  - the exit code is the one docs/cli.md "### Exit codes" documents for that input (the third
    field of each CASES entry below);
  - no crash: no exit status >= 128 or death by a signal, no exit 1 (internal error), no
    sanitizer, abort, assertion or uncaught-exception text; the message starts "bouncecal:";
  - the message names the input where there is one (the file name, the flag or the scene key:
    the fourth field);
  - nothing was written or left behind and no input was modified: every file and directory of
    the working directory (inputs and would-be outputs alike) has the same name and SHA-256
    before and after the command, so a partial output file, a leftover temporary file or an
    overwritten input fails the case.
With --readme the documented copy of the table must equal what is printed (the ctest passes it,
so a changed message or code shows up as drift). Runs in ~6-10 s (the slowest cases fit the
bundled recording).
"""
import argparse
import hashlib
import math
import os
import random
import shlex
import shutil
import struct
import subprocess
import sys
import tempfile
import wave

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RATE_HZ = 48000
TIMEOUT_S = 60  # a case that runs longer is a hang (the slowest takes ~2 s)
CRASH_TEXT = [b"internal error", b"Sanitizer", b"runtime error:", b"terminate called",
              b"Aborted", b"Segmentation fault", b"core dumped", b"Assertion", b"what():",
              b"Check failed"]
NON_UTF8 = b"drop\xff.wav"  # 0xFF never occurs in UTF-8

# Exit codes (docs/cli.md "### Exit codes", include/bouncecal/core/error.hpp).
USAGE, MISSING, NOT_AUDIO, BAD_SAMPLES, SILENCE, NO_BOUNCES = 2, 3, 4, 5, 6, 7
BAD_SCENE, BAD_PARAMETER, OUTPUT, SOME_FAILED = 8, 9, 11, 12

CAL = ["calibrate", "--scene", "scene.toml", "-o", "params.json"]  # a fit that would write
SIM = ["simulate", "--scene", "scene.toml"]

# (input, command after `bouncecal`, expected exit code, strings the message must contain).
CASES = [
    ("missing file", CAL[:1] + ["nofile.wav"] + CAL[1:], MISSING, ["nofile.wav"]),
    ("a directory", CAL[:1] + ["adir"] + CAL[1:], MISSING, ["adir"]),
    ("empty file", CAL[:1] + ["empty.wav"] + CAL[1:], NOT_AUDIO, ["empty.wav"]),
    ("text file named .wav", ["detect", "text.wav"], NOT_AUDIO, ["text.wav"]),
    ("truncated WAV (header says 2 s, 1 s present)", CAL[:1] + ["truncated.wav"] + CAL[1:],
     NOT_AUDIO, ["truncated.wav"]),
    ("WAV with a garbage header", ["detect", "garbage.wav"], NOT_AUDIO, ["garbage.wav"]),
    ("float WAV with a NaN sample", CAL[:1] + ["nan.wav"] + CAL[1:], BAD_SAMPLES, ["nan.wav"]),
    ("float WAV with an Inf sample", ["detect", "inf.wav"], BAD_SAMPLES, ["inf.wav"]),
    ("float WAV with a sample of 1e30", ["analyze", "huge.wav"], BAD_SAMPLES, ["huge.wav"]),
    ("pure digital silence", CAL[:1] + ["silence.wav"] + CAL[1:], SILENCE, ["silence.wav"]),
    ("noise only (no bounces)", CAL[:1] + ["noise.wav"] + CAL[1:], NO_BOUNCES, ["noise.wav"]),
    ("a single impact", ["detect", "single.wav"], NO_BOUNCES, ["single.wav"]),
    ("metronome (clicks every 0.25 s)", CAL[:1] + ["metronome.wav"] + CAL[1:], NO_BOUNCES,
     ["metronome.wav"]),
    ("`--start`/`--end` past the end (9.2 s)", ["detect", "drop.flac", "--start", "100",
                                                 "--end", "110"], NO_BOUNCES, ["drop.flac"]),
    ("unknown channel index", CAL[:1] + ["drop.flac", "--channel", "3"] + CAL[1:], USAGE,
     ["channel 3"]),
    ("scene: TOML syntax error", CAL[:1] + ["drop.flac", "--scene", "syntax.toml",
                                             "-o", "params.json"], BAD_SCENE, ["syntax.toml"]),
    ("scene: unknown key", ["simulate", "--scene", "unknown_key.toml"], BAD_SCENE,
     ["unknown_key.toml", "ball.colour"]),
    ("scene: negative diameter", ["simulate", "--scene", "negative_diameter.toml"], BAD_SCENE,
     ["negative_diameter.toml", "ball.diameter_m"]),
    ("scene: density 0", CAL[:1] + ["drop.flac", "--scene", "zero_density.toml",
                                     "-o", "params.json"], BAD_SCENE,
     ["zero_density.toml", "ball.density_kg_m3"]),
    ("scene file missing", ["simulate", "--scene", "noscene.toml"], MISSING, ["noscene.toml"]),
    ("`--set` unknown name", SIM + ["--set", "bogus=1"], BAD_PARAMETER, ["bogus"]),
    ("`--set k=-1`", CAL[:1] + ["drop.flac"] + CAL[1:] + ["--set", "k=-1"], BAD_PARAMETER,
     ["k = -1"]),
    ("`--set k=1e-308` (subnormal)", SIM + ["--set", "k=1e-308"], BAD_PARAMETER, ["k=1e-308"]),
    ("`--set k=1e309` (overflows)", SIM + ["--set", "k=1e309"], BAD_PARAMETER, ["k=1e309"]),
    ("`--g 1e308`", SIM + ["--g", "1e308"], BAD_SCENE, ["--g"]),
    ("`--impact-speed 1e308`", SIM + ["--impact-speed", "1e308"], BAD_SCENE,
     ["--impact-speed"]),
    ("unknown law name", CAL[:1] + ["drop.flac"] + CAL[1:] + ["--law", "nosuchlaw"],
     BAD_PARAMETER, ["nosuchlaw"]),
    ("expression law `0/0`", SIM + ["--law", "expression", "--expression", "0/0"],
     BAD_PARAMETER, ["0/0"]),
    ("`--impacts`: unsorted times", CAL[:1] + ["drop.flac", "--impacts", "unsorted.txt"] +
     CAL[1:], BAD_SCENE, ["unsorted.txt:2"]),
    ("`--impacts`: a non-numeric time", ["analyze", "--impacts", "non_numeric.txt", "--scene",
                                         "scene.toml"], BAD_SCENE, ["non_numeric.txt:2"]),
    ("parameter file: truncated JSON", ["export", "truncated.json", "--to", "lammps", "-o",
                                        "deck"], BAD_PARAMETER, ["truncated.json"]),
    ("parameter file: a scene file given instead", ["simulate", "--params", "scene.toml"],
     BAD_PARAMETER, ["scene.toml"]),
    ("parameter file: a directory", ["simulate", "--params", "adir"], MISSING, ["adir"]),
    ("parameter file: a later schema", ["export", "newer.json", "--to", "yade", "-o", "deck"],
     BAD_PARAMETER, ["newer.json", "bouncecal.params/9"]),
    ("`-o ''`", CAL[:1] + ["drop.flac"] + CAL[1:-1] + [""], OUTPUT, ["--output"]),
    ("`-o` an existing file, no `--force`", CAL[:1] + ["drop.flac"] + CAL[1:-1] +
     ["existing.json"], OUTPUT, ["existing.json"]),
    ("`-o` the recording itself (`--force`)", CAL[:1] + ["drop.flac"] + CAL[1:-1] +
     ["drop.flac", "--force"], OUTPUT, ["drop.flac"]),
    ("`-o` the scene file itself (`--force`)", CAL[:1] + ["drop.flac"] + CAL[1:-1] +
     ["scene.toml", "--force"], OUTPUT, ["scene.toml"]),
    ("`-o` the `--impacts` file itself (`--force`)", CAL[:1] + ["drop.flac", "--impacts",
                                                                "impacts.txt"] + CAL[1:-1] +
     ["impacts.txt", "--force"], OUTPUT, ["impacts.txt"]),
    ("`--report` the scene file itself (`--force`)", ["report", "drop.flac", "--scene",
                                                       "scene.toml", "-o", "scene.toml",
                                                       "--force"], OUTPUT, ["scene.toml"]),
    ("`-o` in a directory that does not exist", CAL[:1] + ["drop.flac"] + CAL[1:-1] +
     ["nodir/params.json"], OUTPUT, ["nodir"]),
    ("`export -o` an existing directory", ["export", "good_params.json", "--to", "lammps",
                                           "-o", "adir"], OUTPUT, ["adir"]),
    ("non-UTF-8 file name (not audio)", ["detect", NON_UTF8], NOT_AUDIO, [NON_UTF8]),
    ("`calibrate --batch`: one good, two bad", ["calibrate", "--batch", "--scene", "scene.toml",
                                                "drop.flac", "empty.wav", "noise.wav"],
     SOME_FAILED, ["empty.wav", "noise.wav"]),
]


def as_bytes(s):
    return s if isinstance(s, bytes) else s.encode()


def write_wav16(path, samples, rate_hz=RATE_HZ):
    """A mono 16-bit PCM WAV of samples in [-1, 1]."""
    with wave.open(path, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate_hz)
        w.writeframes(b"".join(struct.pack("<h", max(-32767, min(32767, round(x * 32767))))
                               for x in samples))


def write_float_wav(path, samples, rate_hz=RATE_HZ):
    """A mono 32-bit IEEE float WAV (format tag 3; Python's wave writes PCM only)."""
    data = struct.pack("<%df" % len(samples), *samples)
    fmt = struct.pack("<HHIIHH", 3, 1, rate_hz, rate_hz * 4, 4, 32)
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack(
        "<I", len(data)) + data
    with open(path, "wb") as f:
        f.write(b"RIFF" + struct.pack("<I", len(body)) + body)


def noise(seconds, sigma, seed):
    rng = random.Random(seed)
    return [rng.gauss(0.0, sigma) for _ in range(int(seconds * RATE_HZ))]


def metronome(seconds, period_s):
    """Identical clicks (4 kHz, 2 ms decay) every period_s over faint noise: intervals that do
    not shrink, unlike a bounce."""
    out = noise(seconds, 1e-3, 3)
    t0 = 0.5
    while t0 < seconds - 0.1:
        start = int(t0 * RATE_HZ)
        for i in range(int(0.02 * RATE_HZ)):
            t = i / RATE_HZ
            out[start + i] += 0.5 * math.exp(-t / 2e-3) * math.sin(2 * math.pi * 4000.0 * t)
        t0 += period_s
    return out


def make_audio(bouncecal, work):
    """The audio inputs; single.wav through `bouncecal synth` (one impact, then a tail)."""
    open(os.path.join(work, "empty.wav"), "wb").close()
    with open(os.path.join(work, "text.wav"), "w") as f:
        f.write("this is a text file, not a recording\n")
    shutil.copyfile(os.path.join(work, "text.wav"), os.path.join(work.encode(), NON_UTF8))
    write_wav16(os.path.join(work, "truncated.wav"), noise(2.0, 0.05, 1))
    size = os.path.getsize(os.path.join(work, "truncated.wav"))
    os.truncate(os.path.join(work, "truncated.wav"), 44 + (size - 44) // 2)
    rng = random.Random(2)
    with open(os.path.join(work, "garbage.wav"), "wb") as f:
        f.write(b"RIFF" + struct.pack("<I", 4000) + b"WAVEfmt " +
                bytes(rng.randrange(256) for _ in range(4000)))
    for name, bad in [("nan.wav", float("nan")), ("inf.wav", float("inf")), ("huge.wav", 1e30)]:
        samples = noise(1.0, 0.01, 4)
        samples[RATE_HZ // 2] = bad
        write_float_wav(os.path.join(work, name), samples)
    write_wav16(os.path.join(work, "silence.wav"), [0.0] * (2 * RATE_HZ))
    write_wav16(os.path.join(work, "noise.wav"), noise(3.0, 0.05, 5))
    write_wav16(os.path.join(work, "metronome.wav"), metronome(4.0, 0.25))
    # --min-interval 1: the rendering stops before the second impact (the first interval of a
    # 0.2 m drop is ~0.37 s).
    subprocess.run([bouncecal, "synth", "-o", "single.wav", "--min-interval", "1.0", "--seed",
                    "1"], cwd=work, check=True, stdout=subprocess.DEVNULL)


def make_text_inputs(bouncecal, work):
    """Scenes, impacts files, parameter files and the good inputs (copies of data/)."""
    shutil.copyfile(os.path.join(ROOT, "data", "default_steel_copper.flac"),
                    os.path.join(work, "drop.flac"))
    with open(os.path.join(ROOT, "data", "default_steel_copper.toml")) as f:
        scene = f.read()
    files = {
        "scene.toml": scene,
        "syntax.toml": "[ball\ndiameter_m = 0.01\n",
        "unknown_key.toml": scene.replace("[ball]\n", "[ball]\ncolour = \"red\"\n"),
        "negative_diameter.toml": scene.replace("diameter_m = 0.01", "diameter_m = -0.01"),
        "zero_density.toml": scene.replace("density_kg_m3 = 7800.0", "density_kg_m3 = 0.0"),
        "unsorted.txt": "0.5\n0.3\n0.9\n",
        "non_numeric.txt": "0.1\nabc\n0.9\n",
        "impacts.txt": "0.5\n0.87\n1.2\n",
        "truncated.json": '{"schema": "bouncecal.params/2", "law": {"name": ',
        "newer.json": '{"schema": "bouncecal.params/9", "law": {"name": "walton-braun"}}\n',
        "existing.json": "{}\n",
    }
    for name, text in files.items():
        assert text != scene or name == "scene.toml", name + ": the scene edit did not apply"
        with open(os.path.join(work, name), "w") as f:
            f.write(text)
    os.mkdir(os.path.join(work, "adir"))
    subprocess.run([bouncecal, "calibrate", "drop.flac", "--scene", "scene.toml", "-o",
                    "good_params.json"], cwd=work, check=True, stdout=subprocess.DEVNULL)


def snapshot(work):
    """{relative path: SHA-256 (None for a directory)} of everything under work."""
    out = {}
    top = work.encode()
    for dirpath, dirnames, filenames in os.walk(top):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), top)] = None
        for name in filenames:
            path = os.path.join(dirpath, name)
            with open(path, "rb") as f:
                out[os.path.relpath(path, top)] = hashlib.sha256(f.read()).hexdigest()
    return out


def changes(before, after):
    """What a failed command did to the working directory, as short phrases."""
    out = []
    for path in sorted(set(before) | set(after)):
        name = path.decode(errors="backslashreplace")
        if path not in after:
            out.append(name + " removed")
        elif path not in before:
            out.append(name + " left behind")
        elif before[path] != after[path]:
            out.append(name + " modified")
    return out


def check(expected, names, rc, stderr, diff):
    """The failed checks of one case, as phrases (empty: the case passes)."""
    problems = []
    if rc < 0 or rc >= 128:
        problems.append("crashed (status %d)" % rc)
    if rc != expected:
        problems.append("exit %d, documented %d" % (rc, expected))
    for text in CRASH_TEXT:
        if text in stderr:
            problems.append("stderr has %r" % text.decode())
    if not stderr.startswith(b"bouncecal: "):
        problems.append("message does not start with 'bouncecal: '")
    for name in names:
        if as_bytes(name) not in stderr:
            problems.append("message does not name %r" % name)
    problems += diff
    return problems


def run_case(bouncecal, inputs, work, case):
    """Runs one case in `work`, a fresh copy of `inputs` (a case that damages its inputs cannot
    change the next case's); returns (row cells, problems)."""
    what, args, expected, names = case
    shutil.copytree(inputs, work, symlinks=True)
    before = snapshot(work)
    try:
        p = subprocess.run([bouncecal] + [as_bytes(a) for a in args], cwd=work,
                           stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE, timeout=TIMEOUT_S, check=False)
        rc, stderr = p.returncode, p.stderr
    except subprocess.TimeoutExpired:
        rc, stderr = -1, b"(hung: killed after %d s)" % TIMEOUT_S
    problems = check(expected, names, rc, stderr, changes(before, snapshot(work)))
    shown = [as_bytes(a).decode(errors="backslashreplace") for a in args]
    command = "bouncecal " + " ".join(shlex.quote(a) for a in shown)
    first = stderr.decode(errors="backslashreplace").splitlines()[0] if stderr else ""
    return [what, "`%s`" % command, str(rc), cell(first)], problems


def cell(text, limit=160):
    """Text for a Markdown table cell: pipes escaped, cut to `limit` characters."""
    if len(text) > limit:
        text = text[:limit - 1] + "…"
    return text.replace("|", "\\|").replace("<", "&lt;")


HEADER = ["| # | input | command | exit | message (first line of stderr) |",
          "|---|---|---|---|---|"]


def run_all(bouncecal):
    """Runs every case, printing its row as it ends; returns (table lines, failed cases)."""
    lines, failed = list(HEADER), 0
    print("\n".join(HEADER), flush=True)
    with tempfile.TemporaryDirectory(prefix="bad_inputs.") as tmp:
        inputs = os.path.join(tmp, "inputs")
        os.mkdir(inputs)
        make_audio(bouncecal, inputs)
        make_text_inputs(bouncecal, inputs)
        for n, case in enumerate(CASES, 1):
            row, problems = run_case(bouncecal, inputs, os.path.join(tmp, "case%d" % n), case)
            lines.append("| %d | %s |" % (n, " | ".join(row)))
            print(lines[-1], flush=True)
            for p in problems:
                print("bad_inputs: case %d (%s): %s" % (n, case[0], p), file=sys.stderr)
            failed += 1 if problems else 0
    return lines, failed


def readme_table(readme, lines, update):
    """Compares (or with update, replaces) the documented copy of the table: the table lines from
    HEADER on. Returns the number of lines that differ."""
    with open(readme, encoding="utf-8") as f:
        text = f.read().split("\n")
    if HEADER[0] not in text:
        print("bad_inputs: %s has no table starting %r" % (readme, HEADER[0]), file=sys.stderr)
        return 1
    start = text.index(HEADER[0])
    end = start
    while end < len(text) and text[end].startswith("|"):
        end += 1
    old = text[start:end]
    drift = sum(1 for a, b in zip(old, lines) if a != b) + abs(len(old) - len(lines))
    for a, b in zip(old, lines):
        if a != b and not update:
            print("bad_inputs: documented row\n  %s\nis now\n  %s" % (a, b), file=sys.stderr)
    if update and drift:
        with open(readme, "w", encoding="utf-8") as f:
            f.write("\n".join(text[:start] + lines + text[end:]))
        return 0
    return drift


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bouncecal", required=True, help="the bouncecal program to test")
    ap.add_argument("--markdown", action="store_true",
                    help="print only the Markdown table (for docs/reliability.md)")
    ap.add_argument("--readme", help="also check that this file holds the table as printed")
    ap.add_argument("--update", action="store_true", help="with --readme: rewrite its table")
    args = ap.parse_args()
    lines, failed = run_all(os.path.abspath(args.bouncecal))
    if not args.markdown:
        print("\n%d cases, %d failed" % (len(CASES), failed))
    drift = readme_table(args.readme, lines, args.update) if args.readme else 0
    if drift:
        print("bad_inputs: %d lines of the documented table differ (regenerate: --readme %s "
              "--update)" % (drift, args.readme), file=sys.stderr)
    return 1 if failed or drift else 0


if __name__ == "__main__":
    sys.exit(main())
