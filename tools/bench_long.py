#!/usr/bin/env python3
"""bench_long — what detection of a long recording costs: time, system time and peak memory
against the recording's length and rate, side by side with aubioonset on the same file.

    python3 tools/bench_long.py                        # 1, 10, 30, 60 min at 48 and 384 kHz
    python3 tools/bench_long.py --minutes 1 10 --rates 48000 --bouncecal build/bouncecal

Each file is one synthesized minute of steel-on-copper drops (`bouncecal synth --drops 6
--duration 60`, 16-bit WAV) repeated end to end, so an N-minute file holds 6 N drops. Every
figure is a whole process as a user waits for it (`/usr/bin/time`: wall, user and system CPU,
maximum resident set size), the run with the least CPU time (user + system) of --repeat; `bouncecal detect --json` is checked to
find every drop (one sequence per drop). aubioonset runs with `-H 256` (its hop of 5.3 ms at
48 kHz; bouncecal's onsets are ~0.33 ms) on the same file in the same loop (the tools take turns
each repeat; --compare adds another bouncecal build, e.g. main's, checked to print the same JSON), so the ratio column
compares two measurements taken side by side: CPU time (user + system), which a shared machine's
load disturbs far less, and wall time, what a user waits for (bouncecal may use several threads,
--threads; aubioonset uses one). Prints one Markdown table.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import wave


def timed(cmd, stdout_path=None):
    """Runs cmd under /usr/bin/time; returns (wall_s, user_s, sys_s, max_rss_kb)."""
    fmt = "%e %U %S %M"
    with open(stdout_path or os.devnull, "wb") as out:
        p = subprocess.run(["/usr/bin/time", "-f", fmt] + cmd, stdout=out,
                           stderr=subprocess.PIPE, check=False)
    last = p.stderr.decode(errors="replace").strip().splitlines()[-1]
    if p.returncode not in (0, 12):
        sys.exit("bench_long: %s failed (exit %d): %s" % (cmd[0], p.returncode, last))
    wall, user, system, rss = last.split()
    return float(wall), float(user), float(system), int(rss)


def make_file(bouncecal, work, rate, minutes, cache):
    """An N-minute WAV at `rate`: one synthesized minute repeated."""
    one = cache.get(rate)
    if one is None:
        one = os.path.join(work, "one_%d.wav" % rate)
        subprocess.run([bouncecal, "synth", "-o", one, "--force", "--preset", "steel-copper",
                        "--drops", "6", "--drop-gap", "2", "--duration", "60", "--rate",
                        str(rate), "--seed", "3"], check=True, stdout=subprocess.DEVNULL)
        cache[rate] = one
    path = os.path.join(work, "long_%d_%dmin.wav" % (rate, minutes))
    with wave.open(one, "rb") as src:
        params = src.getparams()
        frames = src.readframes(src.getnframes())
    with wave.open(path, "wb") as dst:
        dst.setparams(params)
        for _ in range(minutes):
            dst.writeframes(frames)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bouncecal", default="build/bouncecal")
    ap.add_argument("--minutes", type=int, nargs="+", default=[1, 10, 30, 60])
    ap.add_argument("--rates", type=int, nargs="+", default=[48000, 384000])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--no-aubio", action="store_true")
    ap.add_argument("--threads", type=int, default=None,
                    help="bouncecal detect --threads N (default: its own, one per core)")
    ap.add_argument("--work", default=None, help="directory for the files (default: a temp dir)")
    ap.add_argument("--compare", default=None,
                    help="another bouncecal (e.g. main's build) timed on the same files in the "
                         "same loop, with the same --threads: adds its wall and CPU time and "
                         "the ratios to it, and checks that both print the same JSON")
    a = ap.parse_args()
    aubio = None if a.no_aubio else shutil.which("aubioonset")
    work = a.work or tempfile.mkdtemp(prefix="bench_long_")
    os.makedirs(work, exist_ok=True)
    cache = {}
    cmp_head = (" | --compare wall | user + system | peak memory | --compare / bouncecal (CPU) "
                "| --compare / bouncecal (wall)" if a.compare else "")
    print("| rate | length | drops found | bouncecal wall | user | system | peak memory "
          "| aubioonset -H 256 wall | user + system | peak memory "
          "| aubio / bouncecal (CPU) | aubio / bouncecal (wall)" + cmp_head + " |")
    print("|---" * (12 + (5 if a.compare else 0)) + "|")
    for rate in a.rates:
        for minutes in a.minutes:
            path = make_file(a.bouncecal, work, rate, minutes, cache)
            out_json = os.path.join(work, "detect.json")
            cmp_json = os.path.join(work, "detect_compare.json")
            threads = [] if a.threads is None else ["--threads", str(a.threads)]
            best = ab = other = None
            for _ in range(a.repeat):  # the tools take turns, so that load shifts hit all
                t = timed([a.bouncecal, "detect", "--json", path] + threads, out_json)
                best = t if best is None or t[1] + t[2] < best[1] + best[2] else best
                if aubio:
                    t = timed([aubio, "-i", path, "-H", "256"])
                    ab = t if ab is None or t[1] + t[2] < ab[1] + ab[2] else ab
                if a.compare:
                    t = timed([a.compare, "detect", "--json", path] + threads, cmp_json)
                    other = t if other is None or t[1] + t[2] < other[1] + other[2] else other
            with open(out_json) as f:
                found = len(json.load(f)["sequences"])
            if a.compare:
                with open(out_json, "rb") as f1, open(cmp_json, "rb") as f2:
                    if f1.read() != f2.read():
                        sys.exit("bench_long: %s and %s print different JSON for %s"
                                 % (a.bouncecal, a.compare, path))
            cpu = best[1] + best[2]
            aub = ("%.2f s | %.2f s | %.0f MB | %.2f | %.2f" %
                   (ab[0], ab[1] + ab[2], ab[3] / 1024, (ab[1] + ab[2]) / max(cpu, 1e-3),
                    ab[0] / max(best[0], 1e-3))
                   if ab else "- | - | - | - | -")
            oth = ""
            if other:
                oth = (" | %.2f s | %.2f s | %.0f MB | %.2f | %.2f" %
                       (other[0], other[1] + other[2], other[3] / 1024,
                        (other[1] + other[2]) / max(cpu, 1e-3), other[0] / max(best[0], 1e-3)))
            print("| %d kHz | %d min | %d of %d | %.2f s | %.2f s | %.2f s | %.0f MB | %s%s |" %
                  (rate // 1000, minutes, found, 6 * minutes, best[0], best[1], best[2],
                   best[3] / 1024, aub, oth))
            sys.stdout.flush()
            os.remove(path)
    if not a.work:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
