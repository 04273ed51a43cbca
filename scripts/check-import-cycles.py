#!/usr/bin/env python3
"""Fails when the files of `src/` import each other in a circle.

Builds the file-level graph of the crate's own paths — `use crate::…`, `use super::…`,
`use self::…` and inline `crate::a::b` / `super::x` paths in code — and reports every strongly
connected component of more than one file (Tarjan). A path is charged to the deepest file module
it names: `crate::stats::normal::cdf` is an edge to `src/stats/normal.rs`. Declaring a child
(`mod x;`) is not an edge; using it is. Inline `#[cfg(test)] mod … { … }` blocks are left out,
like the `tests.rs` files nothing imports: tests may use any layer above the code they test.

Usage: python3 scripts/check-import-cycles.py [SRC_DIR]   (default: src, the library)
Exit 0: no circle. Exit 1: the circles, one per line, listed by file.
"""
import re
import sys
from pathlib import Path

PATH = re.compile(r"\b(crate|super|self)((?:::[A-Za-z_][A-Za-z0-9_]*|::\{)+)")
USE = re.compile(r"\buse\s+([^;]+);", re.S)


def strip_comments_and_strings(text):
    """Code without comments, string and char literals (paths in prose are not imports)."""
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    text = re.sub(r'r(#*)".*?"\1', '""', text, flags=re.S)
    text = re.sub(r'"(?:\\.|[^"\\])*"', '""', text, flags=re.S)
    return text


def strip_inline_tests(code):
    """Code without its inline `#[cfg(test)] mod name { ... }` blocks (braces matched)."""
    out, pos = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{", code):
        if m.start() < pos:
            continue
        depth, i = 1, m.end()
        while i < len(code) and depth:
            depth += code[i] == "{"
            depth -= code[i] == "}"
            i += 1
        out.append(code[pos : m.start()])
        pos = i
    out.append(code[pos:])
    return "".join(out)


def module_of(path, src):
    """Module path (list of names) of a file: src/a/b.rs and src/a/b/mod.rs are ['a', 'b']."""
    rel = path.relative_to(src).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return parts


def expand_use(tree):
    """`a::{b, c::{d, e}}` -> [['a','b'], ['a','c','d'], ['a','c','e']] (names only)."""
    tree = re.sub(r"\s+", "", tree)
    tree = re.sub(r"\bas[A-Za-z_][A-Za-z0-9_]*", "", tree)

    def expand(s):
        if "{" not in s:
            return [[p for p in s.split("::") if p]]
        head, _, rest = s.partition("{")
        inner = rest[: rest.rfind("}")]
        items, depth, cur = [], 0, ""
        for ch in inner:
            if ch == "," and depth == 0:
                items.append(cur)
                cur = ""
                continue
            depth += ch == "{"
            depth -= ch == "}"
            cur += ch
        items.append(cur)
        prefix = [p for p in head.split("::") if p]
        out = []
        for it in items:
            if it:
                out.extend(prefix + e for e in expand(it))
        return out or [prefix]

    return expand(tree)


def resolve(names, here, modules):
    """The file module a path names (the deepest one), or None for std and other crates."""
    if not names or names[0] not in ("crate", "super", "self"):
        return None
    if names[0] == "crate":
        base, rest = [], names[1:]
    else:
        # A file a/b.rs or a/b/mod.rs is module a::b: its `super` is a, its `self` is a::b.
        base, rest = list(here), list(names)
        while rest and rest[0] in ("super", "self"):
            if rest[0] == "super":
                base = base[:-1]
            rest = rest[1:]
    path = list(base)
    best = tuple(base) if tuple(base) in modules else None
    for n in rest:
        path.append(n)
        if tuple(path) not in modules:
            break
        best = tuple(path)
    return best


def graph(src):
    files = [p for p in src.rglob("*.rs") if "bin" not in p.relative_to(src).parts]
    modules = {tuple(module_of(p, src)): p for p in files}
    edges = {m: set() for m in modules}
    for m, p in modules.items():
        code = strip_inline_tests(strip_comments_and_strings(p.read_text()))
        paths = []
        for u in USE.finditer(code):
            tree = u.group(1).strip()
            if tree.split("::")[0].strip() in ("crate", "super", "self"):
                paths.extend(expand_use(tree))
        body = USE.sub(" ", code)
        for hit in PATH.finditer(body):
            names = [hit.group(1)] + [n for n in hit.group(2).split("::") if n and n != "{"]
            paths.append(names)
        for names in paths:
            target = resolve(names, list(m), modules)
            if target is not None and target != m:
                edges[m].add(target)
    return modules, edges


def circles(edges):
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def self_test():
    """The checker finds a planted circle (and none in its absence): it can fail."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        src = Path(d) / "src"
        (src / "a").mkdir(parents=True)
        (src / "lib.rs").write_text("pub mod a;\npub mod b;\n")
        (src / "a" / "mod.rs").write_text("pub mod c;\n// use crate::b; in a comment\n")
        (src / "a" / "c.rs").write_text("use crate::b::{Thing, other::{X}};\n")
        (src / "b.rs").write_text('pub struct Thing;\nconst S: &str = "super::a";\n')
        assert circles(graph(src)[1]) == [], "a false circle"
        (src / "b.rs").write_text("pub fn f() { super::a::c::g() }\n")
        assert circles(graph(src)[1]) == [[("a", "c"), ("b",)]], circles(graph(src)[1])
        # A circle through an inline test module is not one.
        (src / "b.rs").write_text("#[cfg(test)]\nmod tests {\n    fn t() { if x { super::a::c::g() } }\n}\n")
        assert circles(graph(src)[1]) == [], "a circle through tests"
    print("self-test passed")
    return 0


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    src = Path(sys.argv[1] if len(sys.argv) > 1 else "src")
    modules, edges = graph(src)
    found = circles(edges)
    for comp in found:
        names = [str(modules[m].relative_to(src.parent)) for m in comp]
        print("import circle: " + " <-> ".join(names))
    if found:
        print(f"{len(found)} import circle(s) among the files of {src}/", file=sys.stderr)
        return 1
    print(f"no import circle among the {len(modules)} files of {src}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
