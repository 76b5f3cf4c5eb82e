# shellcheck shell=bash
# reftree.sh - sourced by compare.sh and inproc/inproc.sh (make bench-compare
# and make bench-inproc): REF's tree as a git worktree, with its bench built
# there by its own Makefile.
#
#   ref_tree TOOL REF   sets FULL (REF's commit), SHORT and DIR (the worktree,
#                       build/compare/<short-sha>, reused when there; `git
#                       worktree prune` and a retry when the add fails), then
#                       builds REF's bin/mpmbench there (make -C DIR
#                       bin/mpmbench -j2; its outputs stay in that tree, whose
#                       files are never changed).  Exits with a message naming
#                       TOOL on any failure.  Run from the top of this tree.
#   default_configs K   prints the configurations both tools run by default,
#                       ';'-separated bin/mpmbench arguments: disks2d and cube3d
#                       on 2 threads with MPM USF, GIMP USF, BSPLINE2 MUSL and
#                       USF, BSPLINE2 MUSL APIC and MPM USL, and MPM USF on 1
#                       thread; cube3d MPM USL with --steps K (it diverges at
#                       step 47 of one simulation, in 36facb3 and this tree
#                       alike: MPM USL's cell-crossing noise at the impact).

ref_tree() {
    local tool=$1 ref=$2
    FULL=$(git rev-parse --verify "$ref^{commit}" 2>/dev/null) || {
        echo "$tool: '$ref' is not a commit" >&2
        exit 2
    }
    SHORT=$(git rev-parse --short "$FULL")
    DIR=build/compare/$SHORT
    if [ -e "$DIR/.git" ]; then
        local have
        have=$(git -C "$DIR" rev-parse HEAD)
        if [ "$have" != "$FULL" ]; then
            echo "$tool: $DIR holds $have, not $FULL; remove it (git worktree remove $DIR)" >&2
            exit 1
        fi
    else
        mkdir -p build/compare
        if ! git worktree add --detach "$DIR" "$FULL" >/dev/null 2>&1; then
            git worktree prune
            git worktree add --detach "$DIR" "$FULL" >/dev/null
        fi
    fi
    echo "$tool: building $SHORT's bin/mpmbench in $DIR" >&2
    mkdir -p "$DIR/build" # ignored by git there: the log adds no file to REF's tree
    make -C "$DIR" -j2 --no-print-directory bin/mpmbench >"$DIR/build/bench-compare-build.log" 2>&1 || {
        echo "$tool: building $SHORT failed; see $DIR/build/bench-compare-build.log" >&2
        tail -20 "$DIR/build/bench-compare-build.log" >&2
        exit 1
    }
}

default_configs() {
    local k=$1 sc out=""
    for sc in disks2d cube3d; do
        out+="--scene $sc --method mpm --update usf --threads 2;"
        out+="--scene $sc --method gimp --update usf --threads 2;"
        out+="--scene $sc --method bspline2 --update musl --threads 2;"
        out+="--scene $sc --method bspline2 --update usf --threads 2;"
        out+="--scene $sc --method bspline2 --update musl --transfer apic --threads 2;"
        if [ $sc = cube3d ]; then
            out+="--scene $sc --method mpm --update usl --threads 2 --steps $k;"
        else
            out+="--scene $sc --method mpm --update usl --threads 2;"
        fi
        out+="--scene $sc --method mpm --update usf --threads 1;"
    done
    printf '%s' "$out"
}
