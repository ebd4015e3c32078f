# tools/gen above BAND_DISKS (1048576) disks fills horizontal bands in parallel: the file must not
# depend on the thread count, no two disks may overlap, and every disk must lie in the box. The whole
# suite only (some 15 s).
if ! all_suite; then
    skip "gen: banded scenes of 1.1e6 disks" "make test-all runs them"
    return
fi

G=$TMP/gen
mkdir -p "$G"
OMP_NUM_THREADS=1 tools/gen 1100000 --fraction 0.3 --steps 0 --mode print --seed 5 > "$G/one.in"
OMP_NUM_THREADS=3 tools/gen 1100000 --fraction 0.3 --steps 0 --mode print --seed 5 > "$G/three.in"
if cmp -s "$G/one.in" "$G/three.in"; then
    pass "gen: banded scene, same file on 1 and 3 threads"
else
    fail "gen: banded scene, same file on 1 and 3 threads" "$(cmp "$G/one.in" "$G/three.in" 2>&1 | head -1)"
fi
# step 0 as the simulator reads it; tools/measure counts the pairs closer than 2r
./omp "$G/one.in" --quiet --dump17 --threads 2 2> "$G/err" | head -n 1100000 > "$G/state"
report=$(tools/measure "$G/one.in" "$G/state" 2>&1)
if [[ $report == *" n=1100000 "* && $report == *" overlap_pairs_per_state=0 "* ]]; then
    pass "gen: banded scene, 1100000 disks without overlap"
else
    fail "gen: banded scene, 1100000 disks without overlap" "$(head -c 300 <<< "$report") $(head -c 200 "$G/err")"
fi
rm -f "$G"/*
