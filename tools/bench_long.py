#!/usr/bin/env python3
"""bench_long — what detection of a long recording costs: time, system time and peak memory
against the recording's length and rate, side by side with aubioonset on the same file, and how
far its detection in blocks agrees with a whole detection of the same audio.

    python3 tools/bench_long.py                        # 1, 10, 30, 60 min at 48 and 384 kHz
    python3 tools/bench_long.py --minutes 1 10 --rates 48000 --bouncecal build/bouncecal

Each file is one synthesized minute of steel-on-copper drops (`bouncecal synth --drops 6
--duration 60`, 16-bit WAV) repeated end to end, so an N-minute file holds 6 N drops. Every
figure is a whole process as a user waits for it (wall, user and system CPU, maximum resident
set size: its wait4 resource usage), of --repeat runs (at least 5 for files of a minute, which
take a tenth of a second) the least wall time and the CPU time and memory of the run with the
least CPU time (user + system): each the least disturbed;
`bouncecal detect --json` is checked to find every drop (one sequence per drop), and compared
with the detection of the synthesized minute alone (one block, whole): every minute of the long
file holds the same samples, so a long file detected in blocks should find, minute by minute,
the same impacts at the same times. Two columns say how far it does: the impacts found against N
times the minute's (and the sum over sequences of the difference in their member counts: the
quiet last impacts of a sequence are decided by its block's own statistics), and the largest
time difference of an impact found in both, over its sigma, among impacts at least 3 dB above
the noise. aubioonset runs with `-H 256` (its hop of 5.3 ms at 48 kHz; bouncecal's onsets are
~0.33 ms) on the same file in the same loop (the tools take turns each repeat; --compare adds
another bouncecal build, e.g. main's, checked to print the same JSON), so the ratio column
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
import time
import wave


def timed(cmd, stdout_path=None):
    """Runs cmd; returns (wall_s, user_s, sys_s, max_rss_kb) of that process (wait4's resource
    usage and a monotonic clock: microseconds, where /usr/bin/time's wall clock had 10 ms, an
    eighth of a 1-minute detection)."""
    with open(stdout_path or os.devnull, "wb") as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err)
        _, status, usage = os.wait4(p.pid, 0)
        wall = time.perf_counter() - start
        p.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        lines = err.read().decode(errors="replace").strip().splitlines()
    if p.returncode not in (0, 12):
        sys.exit("bench_long: %s failed (exit %d): %s"
                 % (cmd[0], p.returncode, lines[-1] if lines else ""))
    return wall, usage.ru_utime, usage.ru_stime, usage.ru_maxrss


def least(kept, t):
    """The least disturbed of a tool's runs so far: the least wall time of any run, and the
    user and system time and peak memory of the run with the least CPU time (user + system).
    On this shared 2-core machine a neighbour's load lengthens a run; two threads lose more
    wall time to it than one, so the run with the least CPU time could have a long wall."""
    if kept is None:
        return t
    wall = min(kept[0], t[0])
    cpu_run = t if t[1] + t[2] < kept[1] + kept[2] else kept
    return (wall,) + tuple(cpu_run[1:])


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


def sequences_of(path):
    """The sequences of a detect --json output: lists of (time_s, sigma_s, snr_db)."""
    with open(path) as f:
        doc = json.load(f)
    return [[(i["time_s"], i["time_sigma_s"], i["snr_db"]) for i in q["impacts"]]
            for q in doc["sequences"]]


def against_minute(long_seqs, minute_seqs):
    """Compares a long file's sequences with the minute's, minute by minute: returns (impacts
    found, sum of |member count difference| over the sequences, largest |dt| / sigma among the
    impacts found in both with SNR >= 3 dB, sequences without a counterpart)."""
    by_start = {}
    for q in minute_seqs:
        by_start[round(q[0][0], 2)] = q
    found = sum(len(q) for q in long_seqs)
    diff = unmatched = 0
    worst = 0.0
    for q in long_seqs:
        shift = 60.0 * int(q[0][0] // 60.0)
        ref = by_start.get(round(q[0][0] - shift, 2))
        if ref is None:
            unmatched += 1
            continue
        diff += abs(len(q) - len(ref))
        ref_times = [r[0] + shift for r in ref]
        for t, sigma, snr in q:
            if snr < 3.0:
                continue
            k = min(range(len(ref_times)), key=lambda j: abs(ref_times[j] - t))
            if abs(ref_times[k] - t) < 0.002 and ref[k][2] >= 3.0:
                worst = max(worst, abs(ref_times[k] - t) / max(sigma, 1e-12))
    return found, diff, worst, unmatched


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bouncecal", default="build/bouncecal")
    ap.add_argument("--minutes", type=int, nargs="+", default=[1, 10, 30, 60])
    ap.add_argument("--rates", type=int, nargs="+", default=[48000, 384000])
    ap.add_argument("--repeat", type=int, default=3)
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
    print("| rate | length | drops found | impacts (minute's x N) | max abs dt / sigma "
          "| bouncecal wall | user | system | peak memory "
          "| aubioonset -H 256 wall | user + system | peak memory "
          "| aubio / bouncecal (CPU) | aubio / bouncecal (wall)" + cmp_head + " |")
    print("|---" * (14 + (5 if a.compare else 0)) + "|")
    minute = {}
    threads = [] if a.threads is None else ["--threads", str(a.threads)]
    for rate in a.rates:
        for minutes in a.minutes:
            path = make_file(a.bouncecal, work, rate, minutes, cache)
            if rate not in minute:  # the synthesized minute, detected whole
                one_json = os.path.join(work, "detect_one.json")
                timed([a.bouncecal, "detect", "--json", cache[rate]] + threads, one_json)
                minute[rate] = sequences_of(one_json)
            out_json = os.path.join(work, "detect.json")
            cmp_json = os.path.join(work, "detect_compare.json")
            best = ab = other = None
            repeat = max(a.repeat, 5) if minutes <= 1 else a.repeat
            for _ in range(repeat):  # the tools take turns, so that load shifts hit all
                best = least(best, timed([a.bouncecal, "detect", "--json", path] + threads,
                                         out_json))
                if aubio:
                    ab = least(ab, timed([aubio, "-i", path, "-H", "256"]))
                if a.compare:
                    other = least(other, timed([a.compare, "detect", "--json", path] + threads,
                                               cmp_json))
            long_seqs = sequences_of(out_json)
            found = len(long_seqs)
            n_imp, n_diff, worst, unmatched = against_minute(long_seqs, minute[rate])
            agree = "%d of %d (%d)%s" % (n_imp, minutes * sum(len(q) for q in minute[rate]),
                                         n_diff, "" if not unmatched else
                                         ", %d sequences unmatched" % unmatched)
            worst_cell = "%.3f" % worst
            if minutes == 1:  # the minute itself: the reference, not a comparison
                agree, worst_cell = "%d (the reference)" % n_imp, "-"
            if a.compare:
                with open(out_json, "rb") as f1, open(cmp_json, "rb") as f2:
                    if f1.read() != f2.read():
                        sys.exit("bench_long: %s and %s print different JSON for %s"
                                 % (a.bouncecal, a.compare, path))
            cpu = best[1] + best[2]
            aub = ("%.3f s | %.3f s | %.0f MB | %.2f | %.2f" %
                   (ab[0], ab[1] + ab[2], ab[3] / 1024, (ab[1] + ab[2]) / max(cpu, 1e-3),
                    ab[0] / max(best[0], 1e-3))
                   if ab else "- | - | - | - | -")
            oth = ""
            if other:
                oth = (" | %.3f s | %.3f s | %.0f MB | %.2f | %.2f" %
                       (other[0], other[1] + other[2], other[3] / 1024,
                        (other[1] + other[2]) / max(cpu, 1e-3), other[0] / max(best[0], 1e-3)))
            print("| %d kHz | %d min | %d of %d | %s | %s | %.3f s | %.3f s | %.3f s | %.0f MB "
                  "| %s%s |" % (rate // 1000, minutes, found, 6 * minutes, agree, worst_cell,
                                best[0], best[1], best[2], best[3] / 1024, aub, oth))
            sys.stdout.flush()
            os.remove(path)
    if not a.work:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
