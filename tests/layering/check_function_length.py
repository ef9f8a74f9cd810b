#!/usr/bin/env python3
"""Fails when a function body in the tree is longer than the limit (docs/conventions.md, "Code").

    check_function_length.py ROOT [--limit N]

Reads every .cc/.h under ROOT's detectors/, station/, daemon/, tools/ and tests/ (skipping
build and fixture folders), strips comments and string literals, and counts the lines from a function's
opening brace to its closing one, for functions at namespace scope and methods defined
outside their class. Lambdas count as part of the function that holds them. Prints each
offender as `path:line: N lines` and exits 1 if there is any.
"""
import argparse
import os
import re
import sys

FOLDERS = ("detectors", "station", "daemon", "tools", "tests")
# An opening brace preceded by `)` and optional qualifiers opens a function body.
FUNCTION_TAIL = re.compile(r"\)\s*(?:const|override|noexcept|final|mutable|->\s*[\w:<>,\s*&]+|\s)*$")
# An opening brace of a namespace, class, struct or extern block opens a scope, not a body.
SCOPE_TAIL = re.compile(r"(?:namespace(?:\s+[\w:]+)?|extern\s+\"\"|(?:class|struct)\s+\w+[^;{}()]*)\s*$")


def strip(source):
    """The source with comments and literals blanked, line breaks kept (so lines still count)."""
    keep_lines = lambda m: "\n" * m.group(0).count("\n")
    source = re.sub(r"//[^\n]*", "", source)
    source = re.sub(r"/\*.*?\*/", keep_lines, source, flags=re.S)
    source = re.sub(r'R"(\w*)\(.*?\)\1"', lambda m: '""' + keep_lines(m), source, flags=re.S)
    source = re.sub(r'"(?:\\.|[^"\\\n])*"', '""', source)
    return re.sub(r"'(?:\\.|[^'\\\n])*'", "''", source)


def long_functions(text, limit):
    """(first line, length) of each function body in `text` longer than `limit` lines."""
    found, stack, line, start = [], [], 1, None
    for i, c in enumerate(text):
        if c == "\n":
            line += 1
        elif c == "{":
            before = text[max(0, i - 300):i]
            if SCOPE_TAIL.search(before):
                kind = "scope"
            elif start is None and all(k == "scope" for k in stack) and FUNCTION_TAIL.search(before):
                kind, start = "function", line
            else:
                kind = "block"
            stack.append(kind)
        elif c == "}" and stack:
            if stack.pop() == "function":
                if line - start + 1 > limit:
                    found.append((start, line - start + 1))
                start = None
    return found


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("root")
    parser.add_argument("--limit", type=int, default=120)
    args = parser.parse_args()
    offenders = 0
    for folder in FOLDERS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(args.root, folder)):
            # Build folders hold generated code; fixture folders hold the checkers' own bad examples.
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(("build", "fixture_")))
            for name in sorted(filenames):
                if not name.endswith((".cc", ".h")):
                    continue
                path = os.path.join(dirpath, name)
                with open(path, encoding="utf-8", errors="replace") as f:
                    text = strip(f.read())
                for start, length in long_functions(text, args.limit):
                    print(f"{os.path.relpath(path, args.root)}:{start}: {length} lines")
                    offenders += 1
    if offenders:
        print(f"{offenders} function(s) over {args.limit} lines: split them along their steps")
        return 1
    print(f"no function over {args.limit} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
