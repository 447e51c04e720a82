#!/usr/bin/env python3
"""Mutation score of the test suite: does it catch small plausible bugs?

Applies single-line mutations (constants, signs, dropped terms, off-by-one samples, ...) from a
mutation list one at a time to a private copy of the tree, rebuilds incrementally, runs the test
suite (stopping at the first failure), restores the file, and prints killed/total with every
survivor. A mutation is *killed* when at least one test fails (or the build/test run crashes or
times out); it *survives* when every test passes.

    tools/mutation_score.py                      # tools/mutations.txt, all mutations
    tools/mutation_score.py --only 3,7           # a subset (ids)
    tools/mutation_score.py --list my.txt        # a reviewer's own list
    tools/mutation_score.py --only a13,a14 --targets tracker_rules_test,sequence_test
                                                 # build and run only these test programs

Mutation list format (tools/mutations.txt): blocks separated by blank lines,

    ## <id>: <short description>
    file: src/fit/kinematics.cpp
    - <exact text to find; must occur exactly once in the file>
    + <replacement text>

`-`/`+` lines may repeat for a multi-line snippet (joined with newlines). A snippet that is not
found exactly once is reported STALE (the code moved on: update the list) and not scored.

The copy lives in --work (default /tmp/bouncecal-mutation); the first run configures and builds
it fully (Release, ccache when available), later runs reuse it. Needs the build dependencies
(tools/install-deps.sh). Takes minutes per mutation on 2 cores: it is a tool, not a CI step.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def parse_list(path):
    text = open(path, encoding="utf-8").read()
    muts = []
    for block in re.split(r"\n\s*\n", text):
        lines = [l for l in block.splitlines() if l.strip() and not l.startswith("# ")]
        if not lines or not lines[0].startswith("## "):
            continue
        m = re.match(r"## *([A-Za-z0-9_.-]+): *(.*)", lines[0])
        if not m:
            sys.exit(f"{path}: bad header line: {lines[0]!r}")
        mid, desc = m.group(1), m.group(2)
        file_, old, new = None, [], []
        for l in lines[1:]:
            if l.startswith("file:"):
                file_ = l[5:].strip()
            elif l.startswith("- ") or l == "-":
                old.append(l[2:])
            elif l.startswith("+ ") or l == "+":
                new.append(l[2:])
            else:
                sys.exit(f"{path}: mutation {mid}: unexpected line {l!r}")
        if not file_ or not old:
            sys.exit(f"{path}: mutation {mid}: needs a file: line and at least one - line")
        muts.append({"id": mid, "desc": desc, "file": file_, "old": "\n".join(old),
                     "new": "\n".join(new)})
    ids = [m["id"] for m in muts]
    dup = {i for i in ids if ids.count(i) > 1}
    if dup:
        sys.exit(f"{path}: duplicate ids {sorted(dup)}")
    return muts


def run(cmd, cwd, timeout=None, env=None):
    t0 = time.time()
    try:
        p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
        return p.returncode, p.stdout + p.stderr, time.time() - t0
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        return -9, out + "\n[timeout]", time.time() - t0


def suites_of(tree, target):
    """The GoogleTest suites of tests/<target>.cpp (ctest names its tests Suite.Name)."""
    text = open(os.path.join(tree, "tests", target + ".cpp"), encoding="utf-8").read()
    return sorted(set(re.findall(r"^\s*TEST(?:_F|_P)?\(\s*(\w+)\s*,", text, re.M)))


def sync_tree(work):
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split("\n")
    for f in files:
        if not f:
            continue
        src, dst = os.path.join(ROOT, f), os.path.join(work, "src_tree", f)
        if not os.path.isfile(src):
            continue
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        # Copy only what changed, so the incremental build stays incremental. A plain copy, with
        # a new modification time: copy2 would keep the source's older time, and make would keep
        # an object built from a mutated copy (an interrupted run) as up to date.
        if not os.path.exists(dst) or open(src, "rb").read() != open(dst, "rb").read():
            shutil.copyfile(src, dst)
            shutil.copymode(src, dst)
    # Files gone from the tree (renamed or deleted) must not linger in the copy: CMake globs.
    tracked = {f for f in files if f}
    for dirpath, dirnames, filenames in os.walk(os.path.join(work, "src_tree")):
        rel_dir = os.path.relpath(dirpath, os.path.join(work, "src_tree"))
        if rel_dir == "build" or rel_dir.startswith("build" + os.sep):
            dirnames[:] = []
            continue
        for name in filenames:
            rel = os.path.normpath(os.path.join(rel_dir, name))
            if rel not in tracked:
                os.remove(os.path.join(dirpath, name))
    # The real recordings: tests read ${source}/../shared/recordings.
    shared = os.path.join(os.path.dirname(ROOT), "shared")
    link = os.path.join(work, "shared")
    if os.path.isdir(shared) and not os.path.exists(link):
        os.symlink(shared, link)


def cheap_first(build):
    """ctest starts the tests with the highest recorded cost first (and last run's failures
    before them). Under --stop-on-failure a mutation is found fastest by the quick unit tests, so
    before each run the recorded costs are inverted: the cheapest tests start first. The order
    changes how soon a failing test is seen, never which tests run on a survivor."""
    path = os.path.join(build, "Testing", "Temporary", "CTestCostData.txt")
    if not os.path.isfile(path):
        return lambda: None
    rows = []
    for line in open(path, encoding="utf-8"):
        if line.strip() == "---":
            break
        parts = line.split()
        if len(parts) == 3:
            rows.append((parts[0], parts[1], float(parts[2])))
    top = max((r[2] for r in rows), default=0.0) + 1.0

    def write():
        with open(path, "w", encoding="utf-8") as f:
            for name, count, cost in rows:
                f.write(f"{name} {count} {top - cost:.6f}\n")
    return write


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--list", default=os.path.join(ROOT, "tools", "mutations.txt"))
    ap.add_argument("--work", default="/tmp/bouncecal-mutation")
    ap.add_argument("--only", default="", help="comma-separated ids")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 2),
                    help="parallel build and test jobs (default 2: the machines are shared)")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the unmutated suite run (only when it passed on these sources)")
    ap.add_argument("--test-timeout", type=int, default=900, help="seconds for one suite run")
    ap.add_argument("--cmake-args", default="",
                    help="extra configure arguments for the copy (e.g. -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld)")
    ap.add_argument("--ctest-args", default="-LE integration|bench",
                    help="extra ctest arguments (default leaves out the DEM-simulator runs and the README-number benchmarks)")
    ap.add_argument("--targets", default="",
                    help="comma-separated test programs (tests/<name>.cpp): build only them and "
                         "run only their tests (a survivor may still be caught by the rest)")
    args = ap.parse_args()

    muts = parse_list(args.list)
    if args.only:
        keep = set(args.only.split(","))
        muts = [m for m in muts if m["id"] in keep]
    tree = os.path.join(args.work, "src_tree")
    build = os.path.join(tree, "build")
    os.makedirs(tree, exist_ok=True)
    sync_tree(args.work)
    env = dict(os.environ)
    if shutil.which("ccache"):
        env.setdefault("CMAKE_CXX_COMPILER_LAUNCHER", "ccache")
    rc, out, _ = run(["cmake", "-S", tree, "-B", build, "-DCMAKE_BUILD_TYPE=Release",
                      "-DBOUNCECAL_WERROR=OFF"] + args.cmake_args.split(), tree, env=env)
    if rc != 0:
        sys.exit("configure failed:\n" + out[-3000:])
    targets = [t for t in args.targets.split(",") if t]
    target_args = ["--target"] + targets if targets else []
    if targets:
        # Only the tests of the programs built: a program left unbuilt must not run stale.
        suites = [s for t in targets for s in suites_of(tree, t)]
        args.ctest_args += " -R (^|/)(" + "|".join(suites) + ")\\."
    print(f"building the unmutated copy in {build} ...", flush=True)
    rc, out, t = run(["cmake", "--build", build, "-j", str(args.jobs)] + target_args, tree,
                     env=env)
    if rc != 0:
        sys.exit("the unmutated tree does not build:\n" + out[-3000:])
    # --no-tests=error: a suite that lost its tests (failed discovery) must not pass.
    ctest = (["ctest", "--stop-on-failure", "--no-tests=error", "-j", str(args.jobs)]
             + args.ctest_args.split())
    if not args.no_baseline:
        rc, out, t = run(ctest, build, timeout=args.test_timeout, env=env)
        if rc != 0:
            sys.exit("the unmutated suite fails; fix that first:\n" + out[-3000:])
        print(f"baseline: build ok, suite passes ({t:.0f} s)\n", flush=True)

    order_tests = cheap_first(build)
    # One "all" build unless --targets: naming the suite's targets instead makes the Makefile
    # generator re-check the globs and the library once per target (slower than relinking the
    # benchmarks); naming a few test programs is faster.
    build_cmd = ["cmake", "--build", build, "-j", str(args.jobs)] + target_args
    results = []
    for m in muts:
        path = os.path.join(tree, m["file"])
        if not os.path.isfile(path):
            results.append((m, "STALE", "file not found", 0.0))
            print(f"[{m['id']}] STALE: {m['file']} not found", flush=True)
            continue
        original = open(path, encoding="utf-8").read()
        count = original.count(m["old"])
        if count != 1:
            results.append((m, "STALE", f"snippet found {count} times", 0.0))
            print(f"[{m['id']}] STALE: snippet found {count} times in {m['file']}", flush=True)
            continue
        t0 = time.time()
        try:
            with open(path, "w", encoding="utf-8") as f:
                f.write(original.replace(m["old"], m["new"]))
            rc, out, _ = run(build_cmd, tree, env=env)
            if rc != 0:
                # A mutation that does not compile tests nothing: reported, not scored.
                errors = [l for l in out.splitlines() if "error" in l.lower()]
                verdict, why = "BUILD_ERROR", (errors or out.strip().splitlines() or [""])[0][:160]
            else:
                order_tests()
                rc, out, _ = run(ctest, build, timeout=args.test_timeout, env=env)
                if rc == 0:
                    verdict, why = "SURVIVED", "every test passed"
                elif rc == -9:
                    verdict, why = "KILLED", f"suite timed out after {args.test_timeout} s"
                else:
                    # Only the "tests FAILED" list (skipped tests are listed too, elsewhere).
                    tail = out.split("The following tests FAILED:", 1)
                    failed = re.findall(r"\d+ - (\S+) \((?!Not Run|Skipped)", tail[-1]
                                        if len(tail) == 2 else "")
                    verdict = "KILLED"
                    why = ("by " + ", ".join(failed[:3])) if failed else out.strip()[-120:]
        finally:
            with open(path, "w", encoding="utf-8") as f:
                f.write(original)
        dt = time.time() - t0
        results.append((m, verdict, why, dt))
        print(f"[{m['id']}] {verdict} ({dt:.0f} s) {m['desc']}: {why}", flush=True)
    # Leave the build matching the unmutated sources.
    run(build_cmd, tree, env=env)

    killed = sum(1 for r in results if r[1] == "KILLED")
    survived = [r for r in results if r[1] == "SURVIVED"]
    scored = killed + len(survived)
    print("\n| id | file | mutation | result | detail |\n|---|---|---|---|---|")
    for m, verdict, why, _ in results:
        detail = why.replace("|", "/").replace("\n", " ")
        print(f"| {m['id']} | {m['file']} | {m['desc']} | {verdict} | {detail} |")
    other = len(results) - scored
    print(f"\nmutation score: {killed}/{scored} killed"
          + (f" ({100.0 * killed / scored:.0f} %)" if scored else "")
          + (f"; {other} not scored (stale or build error)" if other else ""))
    for m, _, _, _ in survived:
        print(f"  survivor {m['id']}: {m['file']}: {m['desc']}")
    return 0 if not survived else 1


if __name__ == "__main__":
    sys.exit(main())
