#!/usr/bin/python3
"""
coverage.py - the summary of `make coverage`: runs gcovr over the counts a
gcov build (build/cov, gcc --coverage) left after the tests, and prints the
line coverage of each library (solver, protocol, store, daemon, ctl), of the
programs over them (mpmctl, mpmweb, the scenes), and in total (all of
them: the product's code; the tests, the benchmarks and the generated
protobuf code are left out).  A header's lines count once, merged over
every object that includes it.  gcovr's table of every file goes to
<build>/coverage.txt.

usage: coverage.py BUILD_DIR   (run from the top of the tree; Makefile:
make coverage)
"""
import json
import os
import subprocess
import sys

# (row, folders); the first five are the libraries
GROUPS = [
    ("solver", ["solver/"]),
    ("protocol", ["protocol/"]),
    ("store", ["server/store/"]),
    ("daemon", ["server/daemon/", "server/mpmd/"]),
    ("ctl", ["clients/ctl/"]),
    ("mpmctl", ["clients/mpmctl/"]),
    ("mpmweb", ["clients/web/"]),
    ("scenes", ["scenes/"]),
]


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: coverage.py BUILD_DIR")
    build = sys.argv[1]
    summary = os.path.join(build, "coverage.json")
    table = os.path.join(build, "coverage.txt")
    cmd = ["gcovr", "--root", ".", "--object-directory", build, "-j", "2",
           "--json-summary", summary, "--txt", table]
    for _, folders in GROUPS:
        for f in folders:
            cmd += ["--filter", f]
    cmd.append(build)
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        sys.exit("coverage: gcovr failed:\n" + r.stderr)
    with open(summary) as fh:
        files = json.load(fh)["files"]
    rows, tot_cov, tot_all = [], 0, 0
    for name, folders in GROUPS:
        cov = sum(f["line_covered"] for f in files if f["filename"].startswith(tuple(folders)))
        n = sum(f["line_total"] for f in files if f["filename"].startswith(tuple(folders)))
        rows.append((name, cov, n))
        tot_cov += cov
        tot_all += n
    rows.append(("total", tot_cov, tot_all))
    print("\nline coverage (%s; every file: %s)" % (build, table))
    print("  %-9s %8s %8s %7s" % ("", "covered", "lines", ""))
    for name, cov, n in rows:
        pct = 100.0 * cov / n if n else 0.0
        print("  %-9s %8d %8d %6.1f%%" % (name, cov, n, pct))
    return 0


if __name__ == "__main__":
    sys.exit(main())
