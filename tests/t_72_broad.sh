# omp's broad phases (omp.c's grid, omp_paths.c's paths, and mixed: slow disks in the grid, the paths
# of fast ones across it): each forced with --broad, and as the cost model chooses them, against seq,
# byte for byte, at 1, 2, 3 and 7 threads, on fast scenes (the assignment's speeds), mixed ones (a few
# disks a quarter of the box per step among slow ones), small N, disks at the walls and paths cut
# short by them, tiny radii; the float build likewise. Then --check (every step against all pairs:
# the events must be exactly those the choice can accept) on scenes of thousands of disks.
B=$TMP/broad
SUF=""
mkdir -p "$B"

broad_scenes() {
    cat <<'SCENES'
fast_walls       300 --assignment --L 150 --steps 20 --mode print
fast_mid         2000 --assignment --L 6000 --steps 10
fast_seed9       700 --assignment --L 2000 --steps 15 --seed 9 --mode print
mixed_gas        2000 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 8 --mode print
mixed_dilute     1500 --fraction 0.02 --speed 2 --fast 0.05 --fast-speed 0.5 --steps 12
mixed_overlap    800 --fraction 0.4 --overlap --speed 1 --fast 0.1 --steps 6 --mode print
tiny_radius      500 --r 1e-4 --L 10 --speed 5e4 --fast 0.1 --steps 10
huge_speed       200 --fraction 0.1 --speed 1e7 --steps 10 --mode print
one_fast         1 --assignment --L 100 --steps 30 --mode print
three_fast       3 --assignment --L 30 --steps 30 --mode print
SCENES
}

# broad_compare NAME INPUT [OPTIONS]: seq's output against omp's with every --broad at 1, 2, 3, 7
# threads; SUF selects the build
broad_compare() {
    local name=$1$SUF in=$2 mode bad=""
    shift 2
    if ! ./seq$SUF "$in" --quiet "$@" > "$B/$name.ref" 2> "$B/err"; then
        fail "broad/$name seq$SUF" "$(head -c 300 "$B/err")"
        return
    fi
    for mode in auto grid paths mixed; do
        local m
        m=$(threads_mismatch "1 2 3 7" "$B/$name.ref" ./omp$SUF "$in" --quiet --broad "$mode" "$@")
        [ -z "$m" ] || bad="$bad $mode:$m"
    done
    if [ -z "$bad" ]; then
        pass "broad/$name: omp$SUF --broad auto, grid, paths, mixed at 1 2 3 7 threads: seq's bytes"
    else
        fail "broad/$name" "$bad"
    fi
}

# (the quick suite: the float build on scenes of up to 800 disks but fast_seed9, whose 700 disks take it
# seconds, as its fast scenes of 2000 disks do with a coarse grid)
while read -r name args; do
    # shellcheck disable=SC2086
    tools/gen $args > "$B/$name.in"
    broad_compare "$name" "$B/$name.in"
    if all_suite || { [ "${args%% *}" -le 800 ] && [ "$name" != fast_seed9 ]; }; then
        SUF=_f32 broad_compare "$name" "$B/$name.in"
    fi
done < <(broad_scenes)

# --lanes: the paths' SIMD screens at each width pass the same pairs (8 lanes: where the processor
# has AVX2, 16 where it has AVX-512F; a SKIP elsewhere): seq's bytes, and as many exact tests as at
# one lane (--stats) on a fast scene of 3000 disks
tools/gen 3000 --assignment --L 6000 --steps 3 --seed 4 > "$B/lanes_big.in"
# tests_verdict NAME TESTS WHAT: pass NAME (WHAT: what held) where $bad is empty and TESTS, the
# "pair tests" line of a --stats run on lanes_big, equals one lane's; else fail it
tests_verdict() {
    [ -s "$B/lanes1.tests" ] && cmp -s "$B/lanes1.tests" "$2" ||
        bad="$bad tests:$(cat "$2") against $(cat "$B/lanes1.tests")"
    if [ -z "$bad" ]; then pass "$1 $3"; else fail "$1" "$bad"; fi
}
./omp "$B/lanes_big.in" --quiet --stats --lanes 1 2>&1 > /dev/null | grep "pair tests" > "$B/lanes1.tests"
for lanes in 1 4 8 16; do
    if ! ./omp "$B/fast_walls.in" --quiet --lanes $lanes > /dev/null 2> "$B/err"; then
        if [ "$lanes" -ge 8 ] && grep -q "lacks" "$B/err"; then
            skip "broad --lanes $lanes" "$(head -c 200 "$B/err")"
        else
            fail "broad --lanes $lanes" "$(head -c 200 "$B/err")"
        fi
        continue
    fi
    bad=""
    for name in fast_walls fast_mid fast_seed9 mixed_gas; do
        ./seq "$B/$name.in" --quiet > "$B/lanes.ref"
        m=$(threads_mismatch "1 3" "$B/lanes.ref" ./omp "$B/$name.in" --quiet --lanes $lanes)
        [ -z "$m" ] || bad="$bad $name:$m"
    done
    ./omp "$B/lanes_big.in" --quiet --stats --lanes $lanes 2>&1 > /dev/null | grep "pair tests" > "$B/lanes.tests"
    tests_verdict "broad --lanes $lanes" "$B/lanes.tests" "at 1 and 3 threads: seq's bytes, one lane's exact tests"
done

# the portable build (omp_portable: the C that processors without SSE2 run, the paths' cells set up
# one axis at a time and screened one pair at a time): seq's bytes under each broad phase, and as
# many exact tests as the default build at one lane
if make -s omp_portable > "$B/err" 2>&1; then
    bad=""
    for name in fast_walls fast_mid mixed_gas mixed_dilute; do
        ./seq "$B/$name.in" --quiet > "$B/portable.ref"
        for mode in auto paths mixed; do
            m=$(threads_mismatch "1 3" "$B/portable.ref" ./omp_portable "$B/$name.in" --quiet --broad $mode)
            [ -z "$m" ] || bad="$bad $name/$mode:$m"
        done
    done
    ./omp_portable "$B/lanes_big.in" --quiet --stats 2>&1 > /dev/null | grep "pair tests" > "$B/portable.tests"
    tests_verdict "broad portable build" "$B/portable.tests" "at 1 and 3 threads: seq's bytes, the default build's exact tests"
else
    fail "broad portable build" "$(head -c 300 "$B/err")"
fi

# the assignment's own random scene (no particle lines) at the sample's density, small N and print
printf '120\n2400\n1\n25\nprint\n' > "$B/random.in"
broad_compare random "$B/random.in" --seed 11
broad_compare "random --substeps 4" "$B/random.in" --seed 11 --substeps 4

# --keep: a mixed step keeps a fast disk's first K events with slow disks only, and finds the step
# again keeping twice as many where the choice would have needed one left out. Every K must give
# seq's bytes; at K = 1 the stats must show disks trimmed and steps found again (that path run).
tools/gen 2000 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 8 > "$B/keep.in"
./seq "$B/keep.in" --quiet > "$B/keep.ref"
for k in 0 1 2; do
    m=$(threads_mismatch "1 2 3 7" "$B/keep.ref" ./omp "$B/keep.in" --quiet --keep $k)
    if [ -z "$m" ]; then
        pass "broad --keep $k at 1 2 3 7 threads: seq's bytes"
    else
        fail "broad --keep $k" "$m"
    fi
done
keep_stats=$(./omp "$B/keep.in" --quiet --stats --threads 3 --keep 1 2>&1 > /dev/null | grep "mixed steps:")
trimmed=$(echo "$keep_stats" | sed -n 's/.*mixed steps: \([0-9]*\) times.*/\1/p')
refound=$(echo "$keep_stats" | sed -n 's/.*; \([0-9]*\) steps found again.*/\1/p')
if [ "${trimmed:-0}" -gt 0 ] && [ "${refound:-0}" -gt 0 ]; then
    pass "broad --keep 1: $trimmed trims, $refound steps found again"
else
    fail "broad --keep 1: trims and steps found again expected" "$keep_stats"
fi

# a fast disk's walk across the slow grid stops once its first K + 1 events with slow disks lie
# before the next line of cells it would visit (omp_paths.c's fast_slow): on a gas whose fast disks
# cross a quarter of a box 140 radii wide, keeping 8 (the default) makes fewer exact tests than
# walking every path whole (--keep 0), with the same bytes (--keep 0 against seq: above)
tools/gen 20000 --fraction 0.2 --speed 0.5 --fast 0.01 --steps 3 > "$B/walk.in"
walk_tests() { sed -n 's/.*: \([0-9]*\) pair tests.*/\1/p' "$1"; }
./omp "$B/walk.in" --quiet --stats --threads 2 --broad mixed --keep 0 > "$B/walk_all.out" 2> "$B/walk_all.err"
./omp "$B/walk.in" --quiet --stats --threads 2 --broad mixed > "$B/walk_first.out" 2> "$B/walk_first.err"
t_all=$(walk_tests "$B/walk_all.err") t_first=$(walk_tests "$B/walk_first.err")
if [ -n "$t_all" ] && [ -n "$t_first" ] && [ "$t_first" -lt "$t_all" ] &&
    cmp -s "$B/walk_all.out" "$B/walk_first.out"; then
    pass "broad mixed: walks stopped early, $t_first exact tests against $t_all with --keep 0, same bytes"
else
    fail "broad mixed: fewer exact tests keeping 8 than all, same bytes" "${t_first:-none} against ${t_all:-none}"
fi

# --stats times the step loop's phases on every thread: each broad phase's run names all seven, and
# their means add up to the step loop (the same clock over the same steps; the end of the parallel
# region is the only time outside them)
for mode in paths grid mixed; do
    err=$(./omp "$B/keep.in" --quiet --stats --threads 3 --broad $mode 2>&1 > /dev/null)
    phases=$(echo "$err" | grep "the step loop's phases, mean of 3 threads:")
    loop=$(echo "$err" | sed -n 's/.*its step loop \([0-9.]*\) s.*/\1/p')
    all=$(echo "$phases" | sed -n 's/.*(\([0-9.]*\) s in all)$/\1/p')
    named=$(echo "$phases" | grep -o -E "(plan|binning|pairs|choice|move|waiting at barriers|output and the final order) [0-9.]+ s" | wc -l)
    if [ "$named" = 7 ] && [ -n "$loop" ] && [ -n "$all" ] &&
        awk -v a="$all" -v l="$loop" 'BEGIN { d = a - l; exit !(d < 0.005 + 0.05 * l && -d < 0.005 + 0.05 * l) }'; then
        pass "broad --stats --broad $mode: seven phases adding up to the step loop ($all against $loop s)"
    else
        fail "broad --stats --broad $mode: phases" "$phases / step loop $loop"
    fi
done

# --check: every step against all pairs, each broad phase (mixed also keeping one event a fast disk:
# the events a trim leaves out are the only ones allowed to be missing); the quick suite one scene
check_scenes=("2000 --fraction 0.05 --speed 3 --fast 0.2 --fast-speed 0.1 --steps 4")
all_suite && check_scenes+=("3000 --assignment --L 6000 --steps 4" \
    "3000 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 4" "2000 --r 1e-6 --L 1 --speed 1e5 --steps 3")
for args in "${check_scenes[@]}"; do
    # shellcheck disable=SC2086
    tools/gen $args > "$B/check.in"
    for prog in omp omp_f32; do
        bad=""
        for mode in auto paths mixed "mixed --keep 1"; do
            # shellcheck disable=SC2086
            ./$prog "$B/check.in" --quiet --check --threads 3 --broad $mode > /dev/null 2> "$B/err" ||
                bad="$bad $mode: $(head -c 200 "$B/err")"
        done
        if [ -z "$bad" ]; then
            pass "broad $prog --check (auto, paths, mixed, mixed --keep 1): $args"
        else
            fail "broad $prog --check: $args" "$bad"
        fi
    done
done
