#!/usr/bin/env python3
"""Regenerates the printed output of the README's worked examples.

Every fenced block of README.md that starts with "$ bouncecal ..." and continues with output
lines is run with the built binary (default build/bouncecal) in a scratch copy of data/, and its
output lines are replaced by what the command prints on stdout. A "..." line in the README
keeps its place: the block keeps as many lines before and after it as it had.
tests/readme_test.cpp checks the same lines, so after a change that moves a number:

    python3 tools/update_readme_examples.py [build/bouncecal]
"""
import os
import shlex
import shutil
import subprocess
import sys
import tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
binary = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build", "bouncecal"))
readme = os.path.join(root, "README.md")
lines = open(readme, encoding="utf-8").read().split("\n")

out, i, in_block = [], 0, False
with tempfile.TemporaryDirectory() as scratch:
    shutil.copytree(os.path.join(root, "data"), os.path.join(scratch, "data"))
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            in_block = not in_block
            out.append(line)
            i += 1
            continue
        if not (in_block and line.startswith("$ bouncecal ")):
            out.append(line)
            i += 1
            continue
        out.append(line)
        j = i + 1
        old = []
        while j < len(lines) and not lines[j].startswith("```") and not lines[j].startswith("$ "):
            old.append(lines[j])
            j += 1
        if old:
            command = line[2:].split("  #")[0]
            args = shlex.split(command)[1:]
            run = subprocess.run([binary] + args, cwd=scratch, capture_output=True, text=True)
            new = run.stdout.rstrip("\n").split("\n")
            if "..." in old:
                k = old.index("...")
                head, tail = k, len(old) - k - 1
                new = new[:head] + ["..."] + (new[len(new) - tail:] if tail else [])
            out.extend(new)
            print(f"README.md:{i + 1}: {command}: {len(new)} lines (exit {run.returncode})")
        i = j
open(readme, "w", encoding="utf-8").write("\n".join(out))
