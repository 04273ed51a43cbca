#!/usr/bin/env python3
"""Fails when a source file of `src/` is over 900 lines or a function in it over 150 lines.

A function is counted from its `fn` line to its closing brace, found by counting braces in the
code with comments, string and char literals blanked out (so a `{` in a string or a comment does
not count). Prints each finding as `path:line: ... N lines`.

Usage: python3 scripts/check-sizes.py [SRC_DIR]   (default: src)
       python3 scripts/check-sizes.py --self-test  (plants an over-long function in a temp dir)
Exit 0: nothing too long. Exit 1: the findings.
"""
import re
import sys
import tempfile
from pathlib import Path

MAX_FILE_LINES = 900
MAX_FN_LINES = 150

FN = re.compile(r"\bfn\s+([A-Za-z_][A-Za-z0-9_]*)")


def blank(text):
    """The text with comments and string/char literals replaced by spaces (newlines kept)."""
    out = []
    i, n = 0, len(text)
    keep = lambda s: "".join(c if c == "\n" else " " for c in s)  # noqa: E731
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(keep(text[i:j]))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(keep(text[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'r(#*)"', text[i:])
            end = text.find('"' + m.group(1), i + len(m.group(0)))
            j = n if end < 0 else end + 1 + len(m.group(1))
            out.append(keep(text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(keep(text[i : j + 1]))
            i = j + 1
        elif c == "'":
            # A char literal ('x', '\n', '\u{..}') — not a lifetime ('a).
            m = re.match(r"'(\\.[^']*|[^\\'\n])'", text[i:])
            if m:
                out.append(keep(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(text):
    """(name, first line, length in lines) of every function with a body."""
    code = blank(text)
    found = []
    for m in FN.finditer(code):
        # The body: the first `{` after the signature at bracket depth 0, unless a `;` comes first
        # (a declaration without a body, as in a trait).
        j, depth = m.end(), 0
        while j < len(code):
            ch = code[j]
            if ch in "([<" and not (ch == "<" and code[j - 1] == "-"):
                depth += ch != "<"
            elif ch in ")]":
                depth -= 1
            elif ch == ";" and depth == 0:
                j = -1
                break
            elif ch == "{" and depth == 0:
                break
            j += 1
        if j < 0 or j >= len(code):
            continue
        level, k = 0, j
        while k < len(code):
            if code[k] == "{":
                level += 1
            elif code[k] == "}":
                level -= 1
                if level == 0:
                    break
            k += 1
        start = code.count("\n", 0, m.start()) + 1
        end = code.count("\n", 0, k) + 1
        found.append((m.group(1), start, end - start + 1))
    return found


def check(src):
    findings = []
    for p in sorted(Path(src).rglob("*.rs")):
        text = p.read_text()
        lines = text.count("\n") + (0 if text.endswith("\n") or not text else 1)
        if lines > MAX_FILE_LINES:
            findings.append(f"{p}:1: file {lines} lines (over {MAX_FILE_LINES})")
        for name, line, length in functions(text):
            if length > MAX_FN_LINES:
                findings.append(f"{p}:{line}: fn {name} {length} lines (over {MAX_FN_LINES})")
    return findings


def self_test():
    with tempfile.TemporaryDirectory() as d:
        src = Path(d) / "src"
        src.mkdir()
        short = 'fn short() {\n    let s = "}}}{";\n    // }\n}\n'
        (src / "a.rs").write_text(short)
        assert check(src) == [], check(src)
        body = "".join(f"    let x{i} = '{{'; /* {{ */\n" for i in range(160))
        (src / "b.rs").write_text("trait T { fn decl(&self); }\n" + short + "pub fn long_one<'a>(x: &'a [u8]) -> Vec<u8> {\n" + body + "}\n")
        found = check(src)
        assert len(found) == 1 and "b.rs:6: fn long_one 162 lines" in found[0], found
        (src / "c.rs").write_text("\n" * 901)
        assert any("c.rs:1: file 901 lines" in f for f in check(src)), check(src)
    print("self-test passed")
    return 0


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    src = sys.argv[1] if len(sys.argv) > 1 else "src"
    findings = check(src)
    for f in findings:
        print(f)
    if findings:
        print(f"{len(findings)} finding(s) in {src}/", file=sys.stderr)
        return 1
    print(f"no file over {MAX_FILE_LINES} lines and no function over {MAX_FN_LINES} lines in {src}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
