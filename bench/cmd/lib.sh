# bench/cmd/lib.sh: helpers that every subcommand of bench.sh shares, above all machine_provenance, the
# one provenance header of every result file; sourced from the repository root after the script has
# defined die (its own name in messages), which integer needs. Never run alone.

words() { echo "${1//,/ }"; }

# Integer from 1000 or 1e3 notation.
integer() {
    awk -v s="$1" 'BEGIN { if (s !~ /^[0-9.]+([eE][0-9]+)?$/ || s + 0 < 1) exit 1; printf "%.0f\n", s }' ||
        die "not a positive integer: '$1'"
}

# The step loop's seconds from a program's stderr in FILE (its last "X s step loop" line); empty if none.
loop_seconds() { sed -n 's/.* \([0-9.e+-]*\) s step loop.*/\1/p' "$1" | tail -n 1; }

# A variable of the Makefile, as make sees it (CC, CFLAGS, ...).
make_var() { make -s --no-print-directory --eval='script-print-%: ; @echo $($*)' "script-print-$1" 2>/dev/null; }

# build_revision REV DIR LOG [TARGETS]: revision REV's TARGETS (default cuda; several in one word, split),
# built in a git worktree at DIR (the benchmark scripts time them beside this tree's build); the build's
# output goes to LOG. Non-zero status when it fails.
build_revision() {
    rm -rf "$2"
    git worktree prune
    # shellcheck disable=SC2086
    git worktree add --detach "$2" "$1" > /dev/null && make -C "$2" -j"$(nproc)" ${4:-cuda} > "$3" 2>&1
}

# build_source FILE OUT LOG: an earlier cuda.cu (say from `git show REV:cuda.cu`) built as OUT against this
# tree's objects, with the Makefile's flags: a copy of the tree without git history cannot build a
# revision (build_revision). The earlier file must use this tree's io.h (a Backend handed to io_main).
# The cuda_*.cuh files it includes must lie beside it (`git archive REV cuda.cu 'cuda_*.cuh'`), or this
# tree's would be built in unseen. The build's output goes to LOG. Non-zero status when it fails.
build_source() {
    local objects h
    for h in $(sed -n 's/^#include "\(cuda_[a-z_]*\.cuh\)".*/\1/p' "$1"); do
        [ -f "$(dirname "$1")/$h" ] || { echo "build_source: $1 includes $h, which is not beside it" > "$3"; return 1; }
    done
    objects=$(make_var BASE)
    mkdir -p "$(dirname "$2")"
    # shellcheck disable=SC2086
    make $objects > /dev/null || return
    # shellcheck disable=SC2046,SC2086
    $(make_var NVCC) $(make_var NVCCFLAGS) -Xcompiler -ffp-contract=off -I. "$1" $objects -o "$2" -lm > "$3" 2>&1
}

# machine_provenance LOAD CORES: the '#' lines of a results file that name the tree (REVISION, or git),
# the machine and the C compiler.
machine_provenance() {
    local hash dirty cc
    if [ -n "${REVISION:-}" ]; then # a copy of the tree without its git checkout names its commit here
        hash=$REVISION dirty="given by REVISION"
    elif hash=$(git rev-parse --short=12 HEAD 2>/dev/null); then
        dirty=$(git status --porcelain --untracked-files=no | grep -q . && echo dirty || echo clean)
    else
        hash="unknown" dirty="not a git checkout"
    fi
    cc=$(make_var CC)
    echo "# git: $hash ($dirty)"
    echo "# date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
    echo "# host: $(uname -n); kernel: $(uname -srm)"
    echo "# load average at start (1, 5, 15 min): $1"
    echo "# cpu: $(awk -F': ' '/^model name/ { print $2; exit }' /proc/cpuinfo 2>/dev/null); cores: $2"
    echo "# cc: $cc: $("$cc" --version 2>/dev/null | head -n 1)"
    echo "# CFLAGS: $(make_var CFLAGS); OMPFLAGS: $(make_var OMPFLAGS)"
    if command -v nvidia-smi > /dev/null 2>&1 && nvidia-smi -L > /dev/null 2>&1; then
        echo "# gpu: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | head -n 1);" \
            "nvcc: $(nvcc --version 2>/dev/null | tail -n 1)"
    fi
}

# base_omp WORK: with BASE_REV (a revision) or BASE_DIR (a folder of an earlier tree's sources, where
# there is no git), that tree's omp built in WORK/base; sets BASE_OMP to it (empty without either) and
# BASE_NAME, and prints the header line naming it.
base_omp() {
    BASE_OMP="" BASE_NAME=""
    [ -n "${BASE_REV:-}" ] || [ -n "${BASE_DIR:-}" ] || return 0
    local dir=$1/base
    rm -rf "$dir" && mkdir -p "$dir"
    if [ -n "${BASE_REV:-}" ]; then
        git archive "$BASE_REV" | tar -x -C "$dir" || die "no revision $BASE_REV"
        BASE_NAME="$BASE_REV ($(git rev-parse --short "$BASE_REV"))"
    else
        [ -f "$BASE_DIR/omp.c" ] || die "BASE_DIR=$BASE_DIR holds no omp.c"
        cp -r "$BASE_DIR"/. "$dir"
        rm -f "$dir"/omp "$dir"/*.o
        BASE_NAME=$BASE_DIR
    fi
    make -s -C "$dir" omp > /dev/null || die "the base's omp did not build"
    BASE_OMP=$dir/omp
    echo "# base: $BASE_NAME, its omp timed in turn with this tree's (rows omp_base)"
}
