#!/usr/bin/python3
"""include_graph.py - the dependency graph between a library's files, and its cycles.

A module is a .c file with its private header of the same name (srv_pool.c
+ srv_pool.h); a private header with no .c of its name joins the one module
whose symbols it declares, or else is a node of its own (srv_daemon_int.h,
store_internal.h); each public header (include/store.h) is a node of its
own, which the library's files implement and include without forming a
circle.  Module A depends on module B
  - at link level when A's object uses a global symbol that B's object
    defines (nm on the objects of a build, build/rel by default), and
  - at header level when a file of A #includes a file of B, or when A's
    private header declares (names) a global symbol that B defines: a
    private header shared by files that each define some of what it
    declares ties them into a circle.
For each library it prints both graphs, every cycle (a strongly connected
component of more than one module, in either graph or in their union) and
the includes that cross into another folder.  Exit status 1 when a library
named in CHECKED has a cycle (make layers, run by make test); the others'
cycles are printed only.

Usage: tests/include_graph.py [--build DIR] [--quiet] [--check]
"""
import os
import re
import subprocess
import sys

# The libraries whose cycles fail the check; extend this one line as a
# library is cleared.
CHECKED = ["solver", "protocol", "server/store", "server/daemon"]

# Every library: its folder (sources in it, public headers in include/).
LIBS = ["solver", "protocol", "server/store", "server/daemon", "clients/ctl", "scenes"]
# Where the headers an #include may name live (resolved by basename).
HEADER_DIRS = ["solver", "protocol", "server", "clients", "scenes", "bench", "build/gen"]

CODE_RE = re.compile(r'/\*.*?\*/|//[^\n]*|"(?:\\.|[^"\\])*"', re.S)
IDENT_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
INCLUDE_RE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def lib_files(lib):
    out = []
    for d in (lib, os.path.join(lib, "include")):
        if os.path.isdir(d):
            out += sorted(os.path.join(d, f) for f in os.listdir(d) if f.endswith((".c", ".h")))
    return out


def all_headers():
    """basename -> [paths] of every header (and included .c) in the tree"""
    idx = {}
    for top in HEADER_DIRS:
        for root, _, files in os.walk(top):
            for f in files:
                if f.endswith((".h", ".c")):
                    idx.setdefault(f, []).append(os.path.join(root, f))
    return idx


def resolve(name, src, lib, idx):
    cands = idx.get(os.path.basename(name), [])
    if not cands:
        return None
    for c in cands:  # the includer's own folder first, then its library's
        if os.path.dirname(c) == os.path.dirname(src):
            return c
    for c in cands:
        if c.startswith(lib + "/"):
            return c
    return cands[0]


def is_public(path):
    return os.path.basename(os.path.dirname(path)) == "include"


def outside_braces(text):
    """text without its {...} blocks: the declarations a header makes, not
    the names an inline function's body or a struct uses"""
    out, depth = [], 0
    for ch in text:
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth = max(depth - 1, 0)
        elif depth == 0:
            out.append(ch)
    return "".join(out)


def declared(path, owner):
    """the modules whose global symbols a header declares (names outside
    comments, strings and braces)"""
    with open(path, encoding="utf-8", errors="replace") as fh:
        idents = set(IDENT_RE.findall(outside_braces(CODE_RE.sub(" ", fh.read()))))
    return {owner[i] for i in idents if i in owner}


def modules(lib, owner):
    """module -> its files.  A private header joins the module of its .c,
    or, with no .c of its name, the one module whose symbols it declares
    (mpp_internal.h: mpp.c's pack and unpack); a public one (include/) is a
    node of its own: the library's interface, which its files implement
    and include without forming a circle"""
    files = lib_files(lib)
    stems = {os.path.splitext(os.path.basename(f))[0] for f in files if f.endswith(".c")}
    mods = {}
    for f in files:
        stem = os.path.splitext(os.path.basename(f))[0]
        if is_public(f):
            m = os.path.basename(f)
        elif stem in stems:
            m = stem
        else:
            owners = declared(f, owner) if f.endswith(".h") else set()
            m = owners.pop() if len(owners) == 1 else os.path.basename(f)
        mods.setdefault(m, []).append(f)
    return mods


def nm_symbols(obj):
    """(defined globals, undefined) of one object"""
    out = subprocess.run(["nm", "-P", obj], capture_output=True, text=True, check=True).stdout
    defs, uses = set(), set()
    for line in out.splitlines():
        parts = line.split()
        if len(parts) < 2:
            continue
        name, kind = parts[0], parts[1]
        if kind == "U":
            uses.add(name)
        elif kind.isupper() or kind in ("i",):
            defs.add(name)
    return defs, uses


def link_graph(lib, build):
    """module -> modules whose symbols it uses; and symbol -> its module"""
    d = os.path.join(build, lib)
    if not os.path.isdir(d):
        return None, {}
    # only the objects of sources that exist (a removed file's object stays)
    srcs = {os.path.basename(f)[:-2] for f in lib_files(lib) if f.endswith(".c")}
    objs = sorted(f for f in os.listdir(d) if f.endswith(".o") and f[:-2] in srcs)
    defs, uses, owner = {}, {}, {}
    for o in objs:
        m = o[:-2]
        defs[m], uses[m] = nm_symbols(os.path.join(d, o))
        for s in defs[m]:
            owner[s] = m
    g = {m: set() for m in defs}
    for m, us in uses.items():
        for s in us:
            if s in owner and owner[s] != m:
                g[m].add(owner[s])
    return g, owner


def include_graph(lib, mods, idx, owner):
    """module -> modules it includes (same library), and -> the modules whose
    functions its private headers declare; and the cross-folder includes as
    (file, header)"""
    of = {f: m for m, fs in mods.items() for f in fs}
    g = {m: set() for m in mods}
    cross = []
    for m, fs in mods.items():
        for f in fs:
            with open(f, encoding="utf-8", errors="replace") as fh:
                text = fh.read()
            if f.endswith(".h") and not is_public(f):
                g[m] |= declared(f, owner) - {m}
            for name in INCLUDE_RE.findall(text):
                h = resolve(name, f, lib, idx)
                if h is None:
                    continue
                if h in of:
                    if of[h] != m:
                        g[m].add(of[h])
                elif not h.startswith(lib + "/"):
                    cross.append((f, h))
    return g, cross


def sccs(g):
    """Tarjan's strongly connected components of more than one node"""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
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

    sys.setrecursionlimit(10000)
    for v in sorted(g):
        if v not in index:
            visit(v)
    return sorted(out)


def main(argv):
    build, quiet = "build/rel", False
    args = list(argv)
    while args:
        a = args.pop(0)
        if a == "--build":
            build = args.pop(0)
        elif a == "--quiet":
            quiet = True
        elif a == "--check":
            pass  # the exit status always reports the checked libraries
        else:
            print(__doc__)
            return 2
    idx = all_headers()
    failed = []
    for lib in LIBS:
        lg, owner = link_graph(lib, build)
        mods = modules(lib, owner)
        ig, cross = include_graph(lib, mods, idx, owner)
        union = {m: set(ig.get(m, ())) | set((lg or {}).get(m, ())) for m in set(ig) | set(lg or {})}
        print(f"== {lib}: {len(mods)} modules" + ("" if lg is not None else f" (no objects in {build})"))
        if not quiet:
            for m in sorted(union):
                links = sorted((lg or {}).get(m, ()))
                incs = sorted(ig.get(m, ()))
                print(f"  {m}")
                if links:
                    print(f"    calls:    {' '.join(links)}")
                if incs:
                    print(f"    includes: {' '.join(incs)}")
            folders = {}
            for f, h in cross:
                folders.setdefault((os.path.dirname(f), os.path.dirname(h)), set()).add(os.path.basename(h))
            for (a, b), hs in sorted(folders.items()):
                print(f"  cross-folder {a} -> {b}: {' '.join(sorted(hs))}")
        bad = False
        for what, graph in (("link", lg or {}), ("include", ig), ("link+include", union)):
            for comp in sccs(graph):
                bad = True
                print(f"  CYCLE ({what}): {' '.join(comp)}")
        if not bad:
            print("  no cycles")
        if lib in CHECKED and lg is None:
            print(f"  no objects in {build}: the link level cannot be checked")
            bad = True
        if bad and lib in CHECKED:
            failed.append(lib)
    if failed:
        print(f"include_graph: cycles in {' '.join(failed)} (checked: {' '.join(CHECKED)})")
        return 1
    print(f"include_graph: no cycles in the checked libraries ({' '.join(CHECKED)})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
