#!/usr/bin/env python3
"""Lists the functions longer than a limit (default 150 lines) in src/ and include/.

    tools/long_functions.py            # every function over 150 lines; exit 1 if any
    tools/long_functions.py --top 20   # the 20 longest, whatever their length

A function is a brace block opened at namespace or class scope by a line that looks like a
definition (a name followed by a parameter list); its length counts the lines from the
signature to the closing brace, lambdas and nested blocks included. Comments, string and
character literals are skipped when matching braces. A heuristic, not a C++ parser: it is
checked against the tree it runs on (tests/long_functions_test runs it).
"""
import argparse
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SIGNATURE = re.compile(r"([A-Za-z_~][A-Za-z0-9_:<>~]*)\s*\([^;]*\)\s*(const)?\s*(noexcept)?\s*"
                       r"(override)?\s*(->\s*[^{;]+)?\s*(:[^;{]*)?\{?\s*$")
NOT_FUNCTIONS = {"if", "for", "while", "switch", "catch", "return", "sizeof", "decltype"}


def strip_code(text):
    """The text with comments and literals blanked (same length, newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            if m:
                end = text.find(")" + m.group(1) + '"', i)
                end = n if end < 0 else end + len(m.group(1)) + 2
                out.append(re.sub(r"[^\n]", " ", text[i:end]))
                i = end
            else:
                out.append(c)
                i += 1
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(c + " " * (min(j, n) - i - 1) + (c if j < n else ""))
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    text = strip_code(open(path, encoding="utf-8", errors="replace").read())
    lines = text.split("\n")
    result = []
    depth_stack = []  # for each open brace: (kind, start_line, name)
    pending = []      # recent non-empty lines at the current scope (for multi-line signatures)
    for ln, line in enumerate(lines, start=1):
        for col, ch in enumerate(line):
            if ch == "{":
                in_function = any(k == "function" for k, _, _ in depth_stack)
                kind, name, start = "block", "", ln
                if not in_function:
                    head = " ".join(pending[-6:] + [line[:col + 1]])
                    head = head[head.rfind(";") + 1:] if ";" in head else head
                    head = head[head.rfind("}") + 1:] if "}" in head else head
                    m = None
                    for m in SIGNATURE.finditer(head.strip()):
                        pass
                    if m and m.group(1).split("::")[-1] not in NOT_FUNCTIONS and \
                            not re.match(r"\s*(namespace|class|struct|enum|union)\b", head):
                        kind, name = "function", m.group(1)
                        back = len([p for p in pending[-6:] if p.strip()])
                        start = ln - min(back, head.count("(") and back)
                depth_stack.append((kind, start, name))
                pending = []
            elif ch == "}":
                if depth_stack:
                    kind, start, name = depth_stack.pop()
                    if kind == "function":
                        result.append((name, start, ln, ln - start + 1))
                pending = []
        if line.strip():
            pending.append(line)
            pending = pending[-6:]
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--limit", type=int, default=150)
    ap.add_argument("--top", type=int, default=0, help="print the N longest instead")
    ap.add_argument("paths", nargs="*", default=["src", "include", "tools", "python"])
    args = ap.parse_args()
    found = []
    for base in args.paths:
        base = os.path.join(ROOT, base) if not os.path.isabs(base) else base
        if os.path.isfile(base):
            files = [base]
        else:
            files = [os.path.join(d, f) for d, _, fs in os.walk(base) for f in fs
                     if f.endswith((".cpp", ".hpp", ".h", ".cc"))]
        for f in sorted(files):
            for name, a, b, n in functions(f):
                found.append((n, os.path.relpath(f, ROOT), a, name))
    found.sort(key=lambda x: (-x[0], x[1], x[2]))
    if args.top:
        rows = found[:args.top]
    else:
        rows = [r for r in found if r[0] > args.limit]
    for n, f, a, name in rows:
        print(f"{n:5d} lines  {f}:{a}  {name}")
    if not args.top:
        print(f"{len(rows)} function(s) over {args.limit} lines")
    return 1 if rows and not args.top else 0


if __name__ == "__main__":
    sys.exit(main())
