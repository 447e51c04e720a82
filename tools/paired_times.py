#!/usr/bin/env python3
"""Whole-process times of two bouncecal builds, measured paired: the same commands run
alternately (A, B, A, B, ...), so that a neighbour's load falls on both alike.

    tools/paired_times.py --a /tmp/before/bouncecal --b build/bouncecal --runs 21
    tools/paired_times.py --a ... --b ... --long          # also a 10-minute recording
    tools/paired_times.py --a build/bouncecal --b build/bouncecal --preload-b "liblapack.so.3"
                                    # what linking a library would cost: B preloads it

Prints a Markdown table: per command the median wall time of each build (ms), the median of
the paired ratios B / A and the median CPU time (user + system) of each. The commands are
what a user runs on the bundled recording (detect, analyze, calibrate, simulate, report) and,
with --long, detect on a 10-minute recording (one synthesized minute repeated, as
tools/bench_long.py makes it) with one and two threads. Run it on a quiet machine, and say how
loaded it was (the load average is printed).
"""
import argparse
import os
import statistics
import subprocess
import tempfile
import time
import wave

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REC = os.path.join(ROOT, "data", "default_steel_copper.flac")
SCENE = os.path.join(ROOT, "data", "default_steel_copper.toml")


def commands(work, long_file):
    out = os.path.join(work, "report.html")
    cmds = [
        ("detect", ["detect", REC, "--json"]),
        ("detect, 2 threads", ["detect", REC, "--json", "--threads", "2"]),
        ("analyze", ["analyze", REC, "--scene", SCENE, "--json"]),
        ("calibrate", ["calibrate", REC, "--scene", SCENE, "--json"]),
        ("simulate", ["simulate", "--scene", SCENE, "--json"]),
        ("simulate 10 000 impacts", ["simulate", "--law", "hunt-crossley-ln", "--json"]),
        ("report", ["report", REC, "--scene", SCENE, "-o", out, "--force"]),
        ("--version", ["--version"]),
    ]
    if long_file:
        cmds += [("detect 10 min, 1 thread", ["detect", long_file, "--json"]),
                 ("detect 10 min, 2 threads", ["detect", long_file, "--json", "--threads", "2"])]
    return cmds


def run(binary, args, env=None):
    """(wall s, cpu s) of one run; its output is discarded."""
    start = time.perf_counter()
    proc = subprocess.Popen([binary] + args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) not in (0, 14):
        raise SystemExit("%s %s failed" % (binary, " ".join(args)))
    return wall, usage.ru_utime + usage.ru_stime


def make_long(binary, work):
    one = os.path.join(work, "one.wav")
    subprocess.run([binary, "synth", "-o", one, "--force", "--preset", "steel-copper", "--drops",
                    "6", "--drop-gap", "2", "--duration", "60", "--seed", "3"], check=True,
                   stdout=subprocess.DEVNULL)
    path = os.path.join(work, "long_10min.wav")
    with wave.open(one, "rb") as src:
        params = src.getparams()
        frames = src.readframes(src.getnframes())
    with wave.open(path, "wb") as dst:
        dst.setparams(params)
        for _ in range(10):
            dst.writeframes(frames)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", required=True, help="the build before (bouncecal binary)")
    ap.add_argument("--b", required=True, help="the build after")
    ap.add_argument("--runs", type=int, default=21, help="runs of each build per command")
    ap.add_argument("--long", action="store_true", help="also detect a 10-minute recording")
    ap.add_argument("--only", default="", help="command names to run, separated by ;")
    ap.add_argument("--preload-b", default="",
                    help="LD_PRELOAD for B's runs (sonames separated by spaces): the start-up "
                    "cost of linking those libraries, with --a and --b the same binary")
    a = ap.parse_args()
    env = {"A": None, "B": None}
    if a.preload_b:
        env["B"] = dict(os.environ, LD_PRELOAD=a.preload_b)
    with tempfile.TemporaryDirectory() as work:
        long_file = make_long(a.a, work) if a.long else None
        print("load average before: %.2f %.2f %.2f" % os.getloadavg())
        print()
        print("| command | A wall (ms) | B wall (ms) | B / A (paired) | A CPU (ms) | B CPU (ms) |")
        print("|---|---|---|---|---|---|")
        only = set(filter(None, a.only.split(";")))
        for name, args in commands(work, long_file):
            if only and name not in only:
                continue
            binaries = {"A": a.a, "B": a.b}
            for k in ("A", "B"):  # warm the page cache
                run(binaries[k], args, env[k])
            wa, wb, ca, cb, ratio = [], [], [], [], []
            for i in range(a.runs):
                order = ("A", "B") if i % 2 == 0 else ("B", "A")
                res = {k: run(binaries[k], args, env[k]) for k in order}
                wa.append(res["A"][0])
                wb.append(res["B"][0])
                ca.append(res["A"][1])
                cb.append(res["B"][1])
                ratio.append(res["B"][0] / res["A"][0])
            med = statistics.median
            print("| %s | %.1f | %.1f | %.3f | %.1f | %.1f |" %
                  (name, 1e3 * med(wa), 1e3 * med(wb), med(ratio), 1e3 * med(ca), 1e3 * med(cb)),
                  flush=True)
        print()
        print("load average after: %.2f %.2f %.2f" % os.getloadavg())


if __name__ == "__main__":
    main()
