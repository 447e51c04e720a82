#!/usr/bin/env python3
"""Checks that the measured tables of README.md and docs/benchmarks.md are what the benchmark programs print.

A measured table in one of these files is preceded by a marker comment naming the program that prints
it (run from the build directory) and how much its numbers may move:

    <!-- measured: bench_detect --quick --seeds 8 --no-aubio; key: 1; tolerance: 0.03;
         times: time per fit (ms) x3; section: hertz-viscoelastic -->
    | preset | RMS(err/sigma) | ... |
    |---|---|...|
    | steel-copper | 1.01 | ... |

The README table is a copy of a table the program prints: the same header line (the program's
table under the first heading line containing `section`, when given), and a subset of its
rows, matched by their first `key` cells (default 1). Every other cell is compared:

- numbers (every number in the cell, in order: "0.98 (+0.20)", "20/20", "A = 5.9e-07 ± 4e-13")
  agree within `tolerance` relative (default 0.02: the programs use fixed seeds, so accuracy
  figures move only when the code changes) or half a unit in the README's last printed digit;
- columns listed in `times` are timings, noisy on a shared machine: they agree within the
  stated factor (x3: between a third and three times the README's value), or both lie within
  20 units of the README's last printed digit (a few-millisecond wall-clock step printed as
  0.003 s moved to 0.017 s under load: too close to the printing resolution to tell);
- anything else (words, "–") must be equal.

    tools/readme_numbers.py [--build DIR] [FILE...]            # check; exit 1 and list every drift
    tools/readme_numbers.py [--build DIR] --update [FILE...]   # rewrite the drifted rows

FILE defaults to README.md and docs/benchmarks.md.

Registered as the ctest `readme_numbers` (label bench): a documented number that drifts from
what its program prints fails the suite.
"""
import argparse
import os
import re
import shlex
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARKER = re.compile(r"<!--\s*measured:(.*?)-->", re.S)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def is_table_line(line):
    return line.lstrip().startswith("|")


def tables_in(lines):
    """[(heading_context, header_line_index, [row line indices])] of every Markdown table."""
    out, heading, i = [], "", 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("#") or (line.strip() and not is_table_line(line) and
                                    i + 1 < len(lines) and not is_table_line(lines[i + 1])):
            heading = line if line.startswith("#") else heading
        if (is_table_line(line) and i + 1 < len(lines) and
                re.match(r"^\s*\|[\s:|-]+\|\s*$", lines[i + 1])):
            rows, j = [], i + 2
            while j < len(lines) and is_table_line(lines[j]):
                rows.append(j)
                j += 1
            out.append((heading, i, rows))
            i = j
            continue
        i += 1
    return out


def parse_marker(text):
    spec = {"command": "", "key": 1, "tolerance": 0.02, "times": {}, "section": ""}
    parts = [p.strip() for p in " ".join(text.split()).split(";") if p.strip()]
    spec["command"] = parts[0]
    for p in parts[1:]:
        name, _, value = p.partition(":")
        name, value = name.strip(), value.strip()
        if name == "key":
            spec["key"] = int(value)
        elif name == "tolerance":
            spec["tolerance"] = float(value)
        elif name == "section":
            spec["section"] = value
        elif name == "times":
            for col in value.split(","):
                m = re.match(r"(.*?)\s+x(\d+(?:\.\d+)?)$", col.strip())
                if not m:
                    sys.exit(f"README marker: times entry {col!r}: expected '<column> x<factor>'")
                spec["times"][m.group(1).strip()] = float(m.group(2))
        else:
            sys.exit(f"README marker: unknown field {name!r} in {text!r}")
    return spec


def half_unit(token):
    """Half a unit in the last printed digit of a number as printed."""
    mant, _, exp = token.lower().partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 0.5 * 10.0 ** (-decimals) * (10.0 ** int(exp) if exp else 1.0)


def compare_cell(readme, program, tolerance, time_factor):
    """None when they agree, else a reason."""
    a, b = NUMBER.findall(readme), NUMBER.findall(program)
    if not a and not b:
        return None if readme == program else "text differs"
    if len(a) != len(b):
        return "numbers differ in count"
    for ta, tb in zip(a, b):
        va, vb = float(ta), float(tb)
        if time_factor:
            if max(abs(va), abs(vb)) <= 40 * half_unit(ta):
                continue  # within 20 printed units of zero: the resolution, not the speed
            if va <= 0 or vb <= 0 or not (va / time_factor <= vb <= va * time_factor):
                return f"time {tb} outside {ta} x/÷ {time_factor:g}"
            continue
        if abs(va - vb) <= max(tolerance * max(abs(va), abs(vb)), 1.01 * half_unit(ta)):
            continue
        return f"{tb} differs from {ta} by more than {tolerance:g} relative"
    return None


def run_program(command, build, cache):
    if command not in cache:
        argv = shlex.split(command)
        exe = os.path.join(build, argv[0])
        if not os.path.isfile(exe):
            sys.exit(f"{exe}: not built (build the project first)")
        p = subprocess.run([exe] + argv[1:], cwd=build, capture_output=True, text=True)
        if p.returncode != 0:
            sys.exit(f"{command}: exit {p.returncode}\n{p.stderr[-2000:]}")
        cache[command] = p.stdout.split("\n")
    return cache[command]


def check_file(path, build, cache, update):
    """(problems, cells checked) of one file's measured tables; with update, rewrites its rows."""
    name = os.path.relpath(path, ROOT)
    text = open(path, encoding="utf-8").read()
    lines = text.split("\n")
    readme_tables = tables_in(lines)
    problems, checked, updates = [], 0, {}
    for m in MARKER.finditer(text):
        spec = parse_marker(m.group(1))
        end_line = text.count("\n", 0, m.end())
        table = next((t for t in readme_tables if t[1] > end_line), None)
        if table is None or any(lines[k].strip() for k in range(end_line + 1, table[1])):
            sys.exit(f"{name}:{end_line + 1}: a measured: marker must be followed by a table")
        _, h, rows = table
        out = run_program(spec["command"], build, cache)
        candidates = [t for t in tables_in(out) if cells(out[t[1]]) == cells(lines[h]) and
                      (not spec["section"] or spec["section"] in t[0])]
        if not candidates:
            problems.append(f"{name}:{h + 1}: `{spec['command']}` prints no table with the "
                            f"header {lines[h].strip()}" +
                            (f" under a heading with {spec['section']!r}" if spec["section"] else ""))
            continue
        header = cells(lines[h])
        prog = {tuple(cells(out[r])[:spec["key"]]): out[r] for r in candidates[0][2]}
        for r in rows:
            rc = cells(lines[r])
            key = tuple(rc[:spec["key"]])
            if key not in prog:
                problems.append(f"{name}:{r + 1}: row {' | '.join(key)} is not printed by "
                                f"`{spec['command']}`")
                continue
            pc = cells(prog[key])
            if len(pc) != len(rc):
                problems.append(f"{name}:{r + 1}: {len(rc)} cells, the program prints {len(pc)}")
                continue
            for col, ra, pa in zip(header, rc, pc):
                checked += 1
                why = compare_cell(ra, pa, spec["tolerance"], spec["times"].get(col, 0.0))
                if why:
                    problems.append(f"{name}:{r + 1}, {col!r} of {' | '.join(key)}: documented "
                                    f"{ra!r}, `{spec['command']}` prints {pa!r} ({why})")
                    updates[r] = prog[key]
    if update and updates:
        for r, new in updates.items():
            lines[r] = new
        open(path, "w", encoding="utf-8").write("\n".join(lines))
        print(f"{name}: updated {len(updates)} row(s)")
    return problems, checked


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--update", action="store_true")
    ap.add_argument("files", nargs="*", default=[os.path.join(ROOT, "README.md"),
                                                 os.path.join(ROOT, "docs", "benchmarks.md")])
    args = ap.parse_args()
    cache, problems, checked = {}, [], 0
    for path in args.files:
        p, c = check_file(path, args.build, cache, args.update)
        problems += p
        checked += c
    if args.update:
        return 0
    for p in problems:
        print(p)
    print(f"{checked} documented cells checked against {len(cache)} program run(s): "
          f"{len(problems)} drift(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
