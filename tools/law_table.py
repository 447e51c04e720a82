#!/usr/bin/env python3
"""The README's table of contact laws, generated from `bouncecal laws` (the registry's rows).

    tools/law_table.py --bouncecal build/bouncecal             # print the table
    tools/law_table.py --bouncecal build/bouncecal --check README.md    # exit 1 if it differs
    tools/law_table.py --bouncecal build/bouncecal --update README.md   # rewrite it in place

The table sits between the lines `<!-- law table: tools/law_table.py -->` and
`<!-- end law table -->`; a ctest (law_table) runs --check, so a law added to the registry
(src/physics/law_registry.cpp) without regenerating the README fails the suite.
"""
import argparse
import csv
import io
import json
import subprocess
import sys

BEGIN = "<!-- law table: tools/law_table.py -->"
END = "<!-- end law table -->"


def table(bouncecal):
    laws = json.loads(subprocess.run([bouncecal, "laws", "--json"], check=True,
                                     capture_output=True, text=True).stdout)["laws"]
    rows = csv.DictReader(io.StringIO(subprocess.run([bouncecal, "laws", "--csv"], check=True,
                                                     capture_output=True, text=True).stdout))
    params = {}
    for r in rows:  # in declaration order (the JSON object is sorted by name)
        params.setdefault(r["law"], []).append("%s (%s)" % (r["parameter"], r["unit"]))
    lines = ["| name | force | parameters (unit) | closed forms |", "|---|---|---|---|"]
    for law in laws:
        forms = ", ".join(law["closed_forms"]) or "— (integrated)"
        lines.append("| `%s` | %s | %s | %s |" % (law["name"], law["formula"],
                                                   ", ".join(params.get(law["name"], [])), forms))
    return "\n".join(lines) + "\n"


def split(text, path):
    begin, end = text.find(BEGIN), text.find(END)
    if begin < 0 or end < begin:
        sys.exit("%s: no '%s' ... '%s' block" % (path, BEGIN, END))
    begin += len(BEGIN) + 1
    return text[:begin], text[begin:end], text[end:]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bouncecal", required=True, help="the bouncecal program")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--check", metavar="README", help="fail if README's table differs")
    group.add_argument("--update", metavar="README", help="rewrite README's table")
    a = ap.parse_args()
    generated = table(a.bouncecal)
    path = a.check or a.update
    if path is None:
        sys.stdout.write(generated)
        return
    with open(path, encoding="utf-8") as f:
        head, current, tail = split(f.read(), path)
    if a.check:
        if current != generated:
            sys.stderr.write("%s: the law table differs from `bouncecal laws`; run "
                             "tools/law_table.py --bouncecal BIN --update %s\n" % (path, path))
            sys.exit(1)
        print("%s: law table matches `bouncecal laws` (%d laws)" %
              (path, generated.count("\n") - 2))
        return
    with open(path, "w", encoding="utf-8") as f:
        f.write(head + generated + tail)


if __name__ == "__main__":
    main()
