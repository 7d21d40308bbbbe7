#!/usr/bin/env python3
"""The compiler-level half of scripts/check-layout.sh (issue 11: index/ owns its layout).

Every .c file of query/, region/, collide/, mesh/, io/ and tools/ is parsed by clang with the
flags of the real build (COMPILE_COMMANDS, a compile_commands.json from a fresh CMake
configuration of SOURCE_DIR), and its AST (-ast-dump=json) is searched for
  - a member access (MemberExpr) whose field is one of struct qk_tree, struct qk__node or
    struct qk__block (index/index_internal.h), whatever the variable, macro or header;
  - an initializer list ({...}, compound literals) of one of those structs (its fields
    set by position or designator);
  - a definition of one of those structs (a copy of the layout).
A use is allowed when the field's name is spelled in index/ (the inline accessors of
index/index_access.h and index/index_internal.h, or a macro defined there); otherwise it is
listed as file:line:col and the field. Files whose project headers test __SSE2__ are parsed
a second time without it, as `make scalar` builds them.

The JSON of a translation unit is 20 to 160 MB, nearly all of it system headers, so it is
not loaded whole: the top-level declarations that mention a layout field are cut out of the
text (clang prints them at an indent of four spaces) and only those are parsed. clang omits
a location's "file" and "line" when they repeat the previous location's, so the file and
line in force where a cut-out declaration begins are read from the text before it.

Usage: check_layout_ast.py COMPILE_COMMANDS SOURCE_DIR [CLANG]. Exits 0 when nothing is
found (printing only the number of files parsed, for check-layout.sh's OK line), 1 with
the list of uses on stderr, 2 when a file has no compile command or clang cannot parse it.
"""
import json
import os
import re
import shlex
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor

MODULES = ("query", "region", "collide", "mesh", "io", "tools")
LAYOUT = ("qk_tree", "qk__node", "qk__block")  # struct tags of index/index_internal.h

TOP = b"\n    {\n"  # a top-level declaration begins (in the translation unit's "inner")
TOP_END = b"\n    }"  # and ends
REF = b'"referencedMemberDecl": "'
COMPLETE = b'"completeDefinition": true'
INIT = b'"kind": "InitListExpr"'
LAYOUT_NAME = re.compile(rb'"name": "(?:%s)",[^{}]*$' % "|".join(LAYOUT).encode())
FILE_KEY = re.compile(rb'"file": ("(?:[^"\\]|\\.)*")')
LINE_KEY = re.compile(rb'"line": (\d+)')
LAYOUT_TYPE = re.compile(r"^(?:(?:const|volatile|restrict) )*struct (%s)$" % "|".join(LAYOUT))


class Source:
    """Where index/ is, and file names as clang prints them, made relative to the tree."""

    def __init__(self, root):
        self.root = os.path.realpath(root)
        self.index = os.path.join(self.root, "index") + os.sep
        self._real = {}

    def real(self, path):
        if path not in self._real:
            self._real[path] = os.path.realpath(path) if path.startswith("/") else None
        return self._real[path]  # (None: <scratch space>, <built-in>)

    def in_index(self, path):
        r = path and self.real(path)
        return bool(r) and r.startswith(self.index)

    def rel(self, path):
        r = path and self.real(path)
        if not r:
            return path or "?"
        return os.path.relpath(r, self.root) if r.startswith(self.root + os.sep) else r


def state_before(text, pos):
    """The file and line of the last location clang printed before byte pos."""
    p = text.rfind(b'"line": ', 0, pos)  # (printed with every "file" too)
    line = int(LINE_KEY.match(text, p).group(1)) if p >= 0 else None
    end = pos
    while True:
        p = text.rfind(b'"file": "', 0, end)
        if p < 0:
            return [None, line]
        q = text.rfind(b"{", 0, p)
        if text[q + 1 : p].strip() == b"" and text[max(0, q - 64) : q].rstrip().endswith(b'"includedFrom":'):
            end = q  # an include stack's entry, not a location
            continue
        return [json.loads(FILE_KEY.match(text, p).group(1)), line]


def chunk_at(text, pos):
    """The byte range of the top-level declaration holding pos."""
    return text.rfind(TOP, 0, pos) + 1, text.find(TOP_END, pos) + len(TOP_END)


def parse_chunk(text, span):
    """A top-level declaration, every location in it given its full file and line."""
    decl = json.loads(text[span[0] : span[1]])
    state = state_before(text, span[0])
    stack = [decl]  # in document order: the order clang printed (and elided) them in
    while stack:
        o = stack.pop()
        if isinstance(o, dict):
            if "offset" in o and "col" in o and "tokLen" in o:  # a location
                if "file" in o:
                    state[0] = o["file"]
                if "line" in o:
                    state[1] = o["line"]
                o["_file"], o["_line"] = state
                continue  # (its includedFrom is no location)
            stack.extend(reversed(list(o.values())))
        elif isinstance(o, list):
            stack.extend(reversed(o))
    return decl


def nodes(node):
    stack = [node]
    while stack:
        o = stack.pop()
        if isinstance(o, dict):
            yield o
            stack.extend(o.get("inner", ()))


def report(src, found, what, loc):
    """Records a use of the layout unless its token is spelled in index/."""
    if "spellingLoc" in loc:
        s, e = loc["spellingLoc"], loc["expansionLoc"]
    else:
        s = e = loc
    spell = (s.get("_file"), s.get("_line"), s.get("col"))
    exp = (e.get("_file"), e.get("_line"), e.get("col"))
    if src.in_index(spell[0]):
        return  # index/'s own inline accessors and macros
    at = spell if src.real(spell[0] or "") else exp  # (<scratch space>: where it expands)
    msg = "%s:%s:%s: %s" % (src.rel(at[0]), at[1], at[2], what)
    if at != exp:
        msg += " (in a macro expanded at %s:%s)" % (src.rel(exp[0]), exp[1])
    found.add(msg)


def scan(src, text, found):
    """Adds to found the layout uses outside index/ in one translation unit's JSON AST.
    Returns the layout structs it saw defined and the number of their field uses (index/'s
    included), for the sanity check."""
    fields, seen, uses = {}, set(), 0
    # The layout structs' definitions, and their fields' ids.
    spans = set()
    p = text.find(COMPLETE)
    while p >= 0:
        if LAYOUT_NAME.search(text, max(0, p - 400), p):
            spans.add(chunk_at(text, p))
        p = text.find(COMPLETE, p + 1)
    for span in spans:
        for o in nodes(parse_chunk(text, span)):
            if o.get("kind") == "RecordDecl" and o.get("name") in LAYOUT and o.get("completeDefinition"):
                seen.add(o["name"])
                report(src, found, "defines struct %s, index/'s layout" % o["name"], o["loc"])
                for fd in nodes(o):
                    if fd.get("kind") == "FieldDecl":
                        fields[fd["id"]] = "struct %s: %s" % (o["name"], fd.get("name", "(unnamed)"))
    if not fields:
        return seen, uses  # the layout is not visible in this file
    # The declarations that name one of the fields, or initialize one of the structs.
    spans = set()
    p = text.find(REF)
    while p >= 0:
        q = p + len(REF)
        if text[q : text.find(b'"', q)].decode() in fields:
            spans.add(chunk_at(text, p))
        p = text.find(REF, q)
    p = text.find(INIT)
    while p >= 0:
        t = text.find(b'"type": {', p)  # (the InitListExpr's: its range holds no "type")
        if any(b'struct %s"' % n.encode() in text[t : text.find(b"}", t)] for n in LAYOUT):
            spans.add(chunk_at(text, p))
        p = text.find(INIT, p + 1)
    for span in sorted(spans):
        for o in nodes(parse_chunk(text, span)):
            kind = o.get("kind")
            if kind == "MemberExpr" and o.get("referencedMemberDecl") in fields:
                uses += 1
                report(src, found, fields[o["referencedMemberDecl"]], o["range"]["end"])
            elif kind == "InitListExpr":
                t = o.get("type", {})
                m = LAYOUT_TYPE.match(t.get("desugaredQualType", t.get("qualType", "")))
                if m:
                    report(src, found, "struct %s: initializer (sets its fields)" % m.group(1), o["range"]["begin"])
    return seen, uses


def included(src, path, incdirs, seen):
    """path and the files of the tree it includes, followed textually (a superset)."""
    if path in seen or not os.path.isfile(path):
        return seen
    seen.add(path)
    with open(path, "rb") as f:
        text = f.read()
    for m in re.finditer(rb'^[ \t]*#[ \t]*include[ \t]*["<]([^">]+)[">]', text, re.M):
        name = m.group(1).decode(errors="replace")
        for d in [os.path.dirname(path)] + incdirs:
            c = os.path.realpath(os.path.join(d, name))
            if c.startswith(src.root + os.sep) and os.path.isfile(c):
                included(src, c, incdirs, seen)
                break
    return seen


def clang_args(entry):
    """An entry's compile command as clang arguments, without the compiler, -c, -o and file."""
    args = entry["arguments"] if "arguments" in entry else shlex.split(entry["command"])
    out, skip = [], False
    for a in args[1:]:
        if skip:
            skip = False
        elif a in ("-o", "-c"):
            skip = a == "-o"
        elif os.path.join(entry["directory"], a) != os.path.join(entry["directory"], entry["file"]):
            out.append(a)
    return out


def parse(job):
    root, clang, path, cwd, args = job
    src = Source(root)
    argv = [clang] + args + ["-w", "-fsyntax-only", "-Xclang", "-ast-dump=json", path]
    r = subprocess.run(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    found = set()
    seen, uses = scan(src, r.stdout, found) if r.returncode == 0 else (set(), 0)
    err = None if r.returncode == 0 else "%s (clang %s):\n%s" % (src.rel(path), " ".join(args), r.stderr.decode(errors="replace"))
    return found, seen, uses, err


def order(msg):
    """By file, then line and column as numbers."""
    f = msg.split(":", 3)
    return [f[0]] + [int(x) if x.isdigit() else 0 for x in f[1:3]] + [msg]


def main():
    if len(sys.argv) < 3:
        print("usage: check_layout_ast.py COMPILE_COMMANDS SOURCE_DIR [CLANG]", file=sys.stderr)
        return 2
    src = Source(sys.argv[2])
    clang = sys.argv[3] if len(sys.argv) > 3 else "clang"
    with open(sys.argv[1]) as f:
        db = json.load(f)
    wanted = set()
    for m in MODULES:
        d = os.path.join(src.root, m)
        if os.path.isdir(d):
            wanted |= {os.path.join(d, n) for n in os.listdir(d) if n.endswith(".c")}
    jobs, covered = [], set()
    for e in db:
        path = os.path.realpath(os.path.join(e["directory"], e["file"]))
        if path not in wanted:
            continue
        covered.add(path)
        args = clang_args(e)
        jobs.append((src.root, clang, path, e["directory"], args))
        incdirs = [a[2:] for a in args if a.startswith("-I") and len(a) > 2]
        incdirs += [args[i + 1] for i, a in enumerate(args[:-1]) if a in ("-I", "-isystem", "-iquote")]
        if any(b"__SSE2__" in open(h, "rb").read() for h in included(src, path, incdirs, set())):
            jobs.append((src.root, clang, path, e["directory"], args + ["-U__SSE2__"]))  # `make scalar`
    missing = sorted(wanted - covered)
    if missing:
        print("check-layout: no compile command for: %s" % " ".join(src.rel(m) for m in missing), file=sys.stderr)
        return 2
    jobs.sort(key=lambda j: -os.path.getsize(j[2]))  # the big ones first: the workers end together
    found, seen, uses, failed = set(), set(), 0, []
    with ProcessPoolExecutor(max_workers=int(os.environ.get("JOBS") or os.cpu_count() or 2)) as ex:
        for f, s, u, err in ex.map(parse, jobs):
            found |= f
            seen |= s
            uses += u
            if err:
                failed.append(err)
    if found:
        print("check-layout: index/'s layout used outside index/ (clang; use index/index_access.h's accessors):", file=sys.stderr)
        print("\n".join(sorted(found, key=order)), file=sys.stderr)
    if failed:
        print("check-layout: clang could not parse, so the layout check is incomplete:", file=sys.stderr)
        print("\n".join(failed), file=sys.stderr)
        return 2
    if found:
        return 1
    if seen != set(LAYOUT) or not uses:
        # index/'s accessors use the fields in every module that includes them: seeing none
        # means this script no longer reads clang's output right, not that all is well.
        print("check-layout: the compiler-level check saw %s defined and %d uses of their fields:"
              " it cannot be working (clang's JSON changed?)" % (sorted(seen) or "no layout struct", uses), file=sys.stderr)
        return 2
    print("%d sources, %d of them also without __SSE2__" % (len(covered), len(jobs) - len(covered)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
