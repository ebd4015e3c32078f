# The periodic box (--periodic, SPEC.md 7 and 7a): no walls, nearest images, coordinates into [0, L).
# - hand-derived cases (tests/periodic/README.md): two disks meeting across an edge (t = 0, then t = 1),
#   pairs across the edges and a corner, a lone disk over the corner, a disk crossing half the box, an
#   overlapped pair parting across an edge; --exact: two disks meeting twice a step, once each way
#   around; seq, omp at 1, 2, 3 and 7 threads, mpi, cuda (refusing only --exact); the exact-rational
#   derivation (tests/hard/derive.py --periodic) of the step cases, and its double model on a scene;
# - omp against seq on generated scenes (gas, fast paths over the edges, mixed, dense, tiny boxes of
#   one or three cells a side) at 1, 2, 3 and 7 threads, under every --broad, --check; --substeps,
#   --exact, --pressure (the same stdout and pressure line), the float builds; mpi at 1 to 3 ranks
#   (up to 8 in make test-all), the strips wrapping;
# - the virial pressure: its line's form, and --exact's Z against Henderson's equation of state;
# - hard cases: triangular crystals at area fraction 0.85 and 0.90 (neighbours 0.07r and 0.008r
#   apart) under --exact: seq and omp the same bytes, no pair closer than 2r by more than 1e-12 of 2r,
#   kinetic energy kept (drift < 1e-12);
# - bad input (a centre at L or below 0, L = 4r, --periodic beside --resume), checkpoints (the same
#   file from seq and omp, resumed across by omp and cuda, format 1 read as a walled run), random
#   placement, tools/gen, check, measure and xyz with --periodic.
Q=$TMP/periodic
mkdir -p "$Q"

# ---- hand-derived cases ----
for f in tests/periodic/*.out; do
    b=$(basename "$f" .out)
    case $b in
        *_exact) ;;
        walled_*) continue ;;
        *) on_backends "periodic/$b" "$f" "${f%.out}.in" --periodic
           continue ;;
    esac
    same_bytes "periodic/$b seq" "$f" ./seq "${f%.out}.in" --periodic --exact --quiet
    bad=$(threads_mismatch "1 2 3 7" "$f" ./omp "${f%.out}.in" --periodic --exact --quiet)
    if [ -z "$bad" ]; then pass "periodic/$b omp at 1, 2, 3 and 7 threads"; else fail "periodic/$b omp" "$bad"; fi
done
if command -v python3 > /dev/null 2>&1; then
    for f in tests/periodic/across_*.in; do
        same_bytes "periodic/$(basename "$f" .in) derivation (exact rationals)" "${f%.in}.out" \
            python3 tests/hard/derive.py --periodic "$f"
    done
    same_bytes "periodic: the independent model of SPEC.md 7 gives edges_print's golden" \
        outputs/periodic/edges_print.out python3 tests/hard/derive.py --inexact --periodic inputs/periodic/edges_print.in
else
    skip "periodic: derivations" "no python3"
fi

# ---- generated scenes: omp against seq ----
# name and tools/gen arguments (--periodic added), one scene a line; the quick suite takes the first five
periodic_scenes() {
    cat <<'SCENES'
gas_print   500 --fraction 0.3 --speed 0.5 --steps 15 --mode print
fast        400 --assignment --L 400 --steps 12
mixed       1500 --fraction 0.2 --speed 0.5 --fast 0.02 --fast-speed 0.2 --steps 8
tiny        2 --L 4.2 --speed 3 --steps 60 --mode print
three_cells 12 --L 9 --speed 2 --steps 40 --mode print
dense       800 --fraction 0.5 --speed 0.3 --steps 12 --mode print
fast_big    2500 --assignment --L 2500 --steps 10
crowded     3000 --fraction 0.4 --speed 1 --fast 0.01 --fast-speed 0.3 --steps 8
half_box    300 --fraction 0.05 --speed 0.5 --fast 0.1 --fast-speed 0.45 --steps 10
SCENES
}
k=0
while read -r name args; do
    k=$((k + 1))
    all_suite || [ "$k" -le 5 ] || break
    # shellcheck disable=SC2086
    ./tools/gen $args --periodic --seed "$k" > "$Q/$name.in"
    ./seq "$Q/$name.in" --periodic --quiet > "$Q/$name.ref"
    bad=$(threads_mismatch "1 2 3 7" "$Q/$name.ref" ./omp "$Q/$name.in" --periodic --quiet)
    for broad in grid paths mixed; do
        bad="$bad$(threads_mismatch "$(all_suite && echo 1 3 7 || echo 3)" "$Q/$name.ref" ./omp "$Q/$name.in" \
            --periodic --quiet --broad $broad | sed "s/ / $broad:/g")"
    done
    if [ -z "$bad" ]; then pass "periodic/$name: omp at 1, 2, 3, 7 threads, every --broad, seq's bytes"
    else fail "periodic/$name omp" "$bad"; fi
done < <(periodic_scenes)
# the independent model of SPEC.md 7 (tests/hard/derive.py) agrees with seq on generated scenes
if command -v python3 > /dev/null 2>&1; then
    for name in three_cells $(all_suite && echo half_box); do
        same_bytes "periodic/$name: the independent model of SPEC.md 7 gives seq's bytes" "$Q/$name.ref" \
            python3 tests/hard/derive.py --inexact --periodic "$Q/$name.in"
    done
fi
# --check: every step's broad phase against all pairs by the nearest image
for name in fast mixed tiny $(all_suite && echo gas_print three_cells crowded half_box); do
    for broad in auto paths mixed; do
        same_bytes "periodic/$name --check --broad $broad" "$Q/$name.ref" \
            ./omp "$Q/$name.in" --periodic --quiet --check --threads 3 --broad $broad
    done
done

# ---- --substeps, --pressure, --exact: stdout and the pressure line, seq against omp ----
# same_run NAME INPUT OPTIONS...: seq's stdout and stderr against omp's at 1, 3 and 7 threads (the
# program's name taken off the pressure line)
same_run() {
    local name=$1 in=$2 t bad=""
    shift 2
    ./seq "$in" --periodic --quiet "$@" > "$Q/run.ref" 2> "$Q/run.err"
    sed 's/^seq: //' "$Q/run.err" > "$Q/run.ref.err"
    for t in 1 3 7; do
        ./omp "$in" --periodic --quiet --threads "$t" "$@" > "$Q/run.out" 2> "$Q/run.err"
        cmp -s "$Q/run.out" "$Q/run.ref" || bad="$bad $t:stdout"
        sed 's/^omp: //' "$Q/run.err" | cmp -s - "$Q/run.ref.err" || bad="$bad $t:stderr($(head -c 150 "$Q/run.err"))"
    done
    if [ -z "$bad" ]; then pass "periodic/$name: omp at 1, 3 and 7 threads, seq's stdout and stderr"
    else fail "periodic/$name" "$bad"; fi
}
same_run "gas_print --substeps 2 --pressure" "$Q/gas_print.in" --substeps 2 --pressure
same_run "fast --pressure" "$Q/fast.in" --pressure
same_run "tiny --exact --pressure" "$Q/tiny.in" --exact --pressure
same_run "three_cells --exact" "$Q/three_cells.in" --exact
all_suite && same_run "mixed --exact --pressure" "$Q/mixed.in" --exact --pressure
all_suite && same_run "dense --substeps 4 --pressure" "$Q/dense.in" --substeps 4 --pressure

# --exact on all threads (omp_exact.c): the strips wrap (the first and last are neighbours across the
# edge) and the band over the edge holds the columns on both sides of it. A gas at area fraction 0.5
# and fast disks crossing strips, at 1, 2, 3, 7 and 16 threads (the quick suite: 1, 2, 7): seq's bytes,
# pressure line and event count, some events in the bands; --check (every window against all pairs by
# the nearest image).
tools/gen 1000 --fraction 0.5 --speed 1 --steps 5 --periodic --seed 11 > "$Q/half.in"
tools/gen 1000 --fraction 0.3 --speed 0.5 --fast 0.01 --fast-speed 0.1 --steps 4 --periodic --seed 12 > "$Q/crossing.in"
for name in half crossing; do
    ./seq "$Q/$name.in" --periodic --exact --pressure --stats --quiet > "$Q/x.ref" 2> "$Q/x.ref.err"
    total=$(exact_events "$Q/x.ref.err")
    pressure=$(grep 'pressure' "$Q/x.ref.err" | sed 's/^seq: //')
    bad="" threads=$(all_suite && echo "1 2 3 7 16" || echo "1 2 7")
    for t in $threads; do
        ./omp "$Q/$name.in" --periodic --exact --pressure --stats --quiet --threads $t > "$Q/x.out" 2> "$Q/x.err"
        split=$(exact_split "$Q/x.err")
        read -r in_strips in_bands in_seq <<< "$split"
        if ! cmp -s "$Q/x.out" "$Q/x.ref"; then bad="$bad $t:stdout"
        elif [ "$(grep 'pressure' "$Q/x.err" | sed 's/^omp: //')" != "$pressure" ]; then bad="$bad $t:pressure"
        elif [ "$(exact_events "$Q/x.err")" != "$total" ] ||
            [ "$((in_strips + in_bands + in_seq))" != "$total" ] || { [ $t -gt 1 ] && [ "$in_bands" = 0 ]; }; then
            bad="$bad $t:events($split of $total)"
        fi
    done
    if [ -z "$bad" ] && [ -n "$total" ] && [ -n "$pressure" ]; then
        pass "periodic/$name --exact: omp at $threads threads, seq's bytes, pressure line and $total events, some in the bands"
    else
        fail "periodic/$name --exact on all threads" "$bad $(head -c 200 "$Q/x.err")"
    fi
    for t in 2 $(all_suite && echo 7); do
        same_bytes "periodic/$name --exact --check --threads $t" "$Q/x.ref" \
            ./omp "$Q/$name.in" --periodic --exact --pressure --check --quiet --threads $t
    done
done
pattern='^seq: pressure \(periodic box, collision virial\): N kT = [0-9.e+-]+, virial [0-9.e+-]+ over 15 time units: P = [0-9.e+-]+, Z = P L\^2 / \(N kT\) = [0-9.e+-]+ \+- [0-9.e+-]+ \(standard error of 10 block means\)$'
./seq "$Q/gas_print.in" --periodic --quiet --pressure > /dev/null 2> "$Q/p.err"
if [ "$(wc -l < "$Q/p.err")" = 1 ] && grep -Eq "$pattern" "$Q/p.err"; then
    pass "periodic --pressure: one line, P, Z and its standard error over 10 blocks"
else
    fail "periodic --pressure: the line" "$(head -c 300 "$Q/p.err")"
fi
# --exact's Z on a gas at area fraction 0.3 against Henderson's equation of state (1 + f^2/8) / (1 - f)^2
# = 2.064: within 4 standard errors and 3% (the run is a few thousand collisions a disk)
if all_suite; then
    ./tools/gen 600 --periodic --fraction 0.3 --speed 1 --steps 300 --seed 31 > "$Q/eos.in"
    ./omp "$Q/eos.in" --periodic --exact --pressure --quiet --threads 2 > /dev/null 2> "$Q/eos.err"
    read -r z err < <(sed -n 's/.*Z = P L^2 \/ (N kT) = \([0-9.e+-]*\) +- \([0-9.e+-]*\) .*/\1 \2/p' "$Q/eos.err")
    if awk -v z="$z" -v e="$err" 'BEGIN { h = (1 + 0.09 / 8) / 0.49; d = z - h; if (d < 0) d = -d
                                         exit !(z != "" && d < 4 * e + 0.03 * h) }'; then
        pass "periodic --exact --pressure: Z = $z +- $err at area fraction 0.3 (Henderson: 2.064)"
    else
        fail "periodic --exact --pressure: Z at area fraction 0.3" "Z = $z +- $err, Henderson 2.064"
    fi
fi

# ---- the float builds agree with each other ----
for name in fast mixed; do
    ./seq_f32 "$Q/$name.in" --periodic --quiet > "$Q/$name.f32"
    bad=$(threads_mismatch "1 3" "$Q/$name.f32" ./omp_f32 "$Q/$name.in" --periodic --quiet)
    bad="$bad$(threads_mismatch "2" "$Q/$name.f32" ./omp_f32 "$Q/$name.in" --periodic --quiet --broad paths)"
    if [ -z "$bad" ]; then pass "periodic/$name float: omp_f32 at 1, 2, 3 threads, seq_f32's bytes"
    else fail "periodic/$name float" "$bad"; fi
done

# ---- mpi: the strips wrap ----
if have_mpi; then
    mpi_env
    for name in fast gas_print tiny $(all_suite && echo mixed three_cells dense fast_big half_box); do
        bad=""
        for c in $(all_suite && echo 1 2 3x2 4 8 || echo 3); do
            p=${c%x*} t=1
            [ "$c" != "$p" ] && t=${c#*x}
            if ! run_mpi "$p" "$t" "$Q/$name.in" --periodic --quiet --check > "$Q/m.out" 2> "$Q/m.err"; then
                bad="$bad $c:exit($(head -c 150 "$Q/m.err"))"
            elif ! cmp -s "$Q/m.out" "$Q/$name.ref"; then
                bad="$bad $c:differs"
            fi
        done
        if [ -z "$bad" ]; then pass "periodic/$name mpi --check: seq's bytes"; else fail "periodic/$name mpi" "$bad"; fi
    done
    if all_suite; then # the cuts moved every step
        same_bytes "periodic/gas_print mpi --balance 1 at 5 ranks" "$Q/gas_print.ref" \
            run_mpi 5 1 "$Q/gas_print.in" --periodic --quiet --balance 1 --check
    fi
    ./seq "$Q/gas_print.in" --periodic --quiet --substeps 2 --pressure > "$Q/ms.ref" 2> "$Q/ms.err"
    run_mpi 3 1 "$Q/gas_print.in" --periodic --quiet --substeps 2 --pressure > "$Q/m.out" 2> "$Q/m.err"
    if cmp -s "$Q/m.out" "$Q/ms.ref" && [ "$(sed 's/^mpi: //' "$Q/m.err")" = "$(sed 's/^seq: //' "$Q/ms.err")" ]; then
        pass "periodic mpi --substeps 2 --pressure at 3 ranks: seq's stdout and pressure line"
    else
        fail "periodic mpi --pressure" "$(head -c 300 "$Q/m.err")"
    fi
    printf '3\n10\n1\n2\nperf\n0 1 1 0 0\n1 5 10 0 0\n2 5 5 0 0\n' > "$Q/bad_mpi.in"
    expect_mpi_error "periodic mpi: a centre at L, seq's line" "bad_mpi.in:7: y must be within \[0, L\)" \
        "$Q/bad_mpi.in" --periodic
else
    skip "periodic mpi" "no mpirun or no ./mpi"
fi

# ---- hard cases: triangular crystals under --exact ----
# N = 418 (19 disks a row, 22 rows, stretched 0.28% to fill the box), speeds up to r/2 a step. The
# quick suite: about 350 collisions a disk at 0.85, 190 at 0.90; make test-all: 1e4 at 0.85 and at 0.90
# (some 1400 and 150 steps), at r = 1 (2r a power of two, where a response through n / |n| gained
# energy on average: 1.9e-12 over 1e4 collisions a disk; exact_bounce holds n.n exactly) and at r = 1.3.
# crystal PHI STEPS R: omp --exact at 2 threads on the crystal into $Q/crystal.ref; sets pen (the
# deepest overlap over r), drift (relative, of the kinetic energy) and per (collisions a disk)
crystal() {
    ./tools/gen 418 --lattice --fraction "$1" --speed 0.5 --steps "$2" --seed 3 --r "$3" > "$Q/crystal.in" 2> /dev/null
    ./omp "$Q/crystal.in" --periodic --exact --quiet --dump17 --threads 2 > "$Q/crystal.ref"
    local report pairs
    report=$(tools/measure --periodic "$Q/crystal.in" "$Q/crystal.ref")
    read -r pen drift pairs < <(tr ' ' '\n' <<< "$report" | sed -n 's/^\(max_penetration_over_r\|energy_drift\|pair_collisions\)=//p' | tr '\n' ' ')
    per=$(awk -v p="$pairs" 'BEGIN { printf "%.0f", 2 * p / 418 }')
}
for phi in 0.85 0.90; do
    if [ "$phi" = 0.85 ]; then steps=$(all_suite && echo 1450 || echo 50); else steps=$(all_suite && echo 156 || echo 3); fi
    crystal "$phi" "$steps" 1
    if awk -v p="$pen" -v d="$drift" -v c="$per" -v need="$(all_suite && echo 9000 || echo 0)" \
        'BEGIN { exit !(p <= 2e-12 && d < 1e-12 && c >= need) }'; then
        pass "periodic crystal $phi --exact: $per collisions a disk, deepest overlap $pen r, energy drift $drift"
    else
        fail "periodic crystal $phi --exact" "$per collisions a disk, deepest overlap $pen r (at most 2e-12), drift $drift (at most 1e-12)"
    fi
    if all_suite || [ "$phi" = 0.90 ]; then
        same_bytes "periodic crystal $phi --exact: seq's bytes" "$Q/crystal.ref" \
            ./seq "$Q/crystal.in" --periodic --exact --quiet --dump17
    fi
    bad=$(threads_mismatch "1 3 7" "$Q/crystal.ref" ./omp "$Q/crystal.in" --periodic --exact --quiet --dump17)
    if [ -z "$bad" ]; then pass "periodic crystal $phi --exact: omp at 1, 2, 3 and 7 threads alike"
    else fail "periodic crystal $phi --exact omp" "$bad"; fi
done
if all_suite; then
    crystal 0.85 1450 1.3
    if awk -v p="$pen" -v d="$drift" -v c="$per" 'BEGIN { exit !(p <= 2e-12 && d < 1e-12 && c >= 9000) }'; then
        pass "periodic crystal 0.85 at r = 1.3 --exact: $per collisions a disk, deepest overlap $pen r, energy drift $drift < 1e-12"
    else
        fail "periodic crystal 0.85 at r = 1.3 --exact" "$per collisions a disk, deepest overlap $pen r, drift $drift"
    fi
fi

# ---- bad input: one line, nothing on stdout ----
printf '2\n10\n1\n3\nperf\n0 10 5 0 0\n1 2 5 0 0\n' > "$Q/at_L.in"
printf '2\n10\n1\n3\nperf\n0 5 5 0 0\n1 2 -0.5 0 0\n' > "$Q/below.in"
printf '2\n4\n1\n3\nperf\n' > "$Q/four_r.in"
printf '2\n4.0000001\n1\n3\nperf\n0 1 1 0.5 0\n1 3 3 0 0\n' > "$Q/just_fits.in"
for prog in $(backend_list); do
    expect_error "periodic $prog: a centre at x = L" "at_L.in:6: x must be within \[0, L\) = \[0, 10\) with --periodic \(found '10'\)" \
        ./$prog "$Q/at_L.in" --periodic
    expect_error "periodic $prog: a centre below 0" "below.in:7: y must be within \[0, L\)" ./$prog "$Q/below.in" --periodic
    expect_error "periodic $prog: L = 4r" "four_r.in:3: with --periodic the radius r must satisfy 4r < L" \
        ./$prog "$Q/four_r.in" --periodic
    expect_error "periodic $prog: --periodic beside --resume" "--resume takes .*--periodic.* from the checkpoint" \
        ./$prog --resume "$Q/none.ck" --periodic
done
same_bytes "periodic: L just above 4r runs" <(./seq "$Q/just_fits.in" --periodic --quiet) ./omp "$Q/just_fits.in" --periodic --quiet
if have_gpu; then
    expect_error "periodic: cuda refuses --periodic --exact" "--exact is not supported by cuda" \
        ./cuda "$Q/just_fits.in" --periodic --exact
else
    skip "periodic: cuda refuses --periodic --exact" "no GPU"
fi

# ---- checkpoints ----
./seq "$Q/gas_print.in" --periodic --pressure --quiet --checkpoint "$Q/seq.ck" --checkpoint-every 6 > /dev/null 2>&1
./omp "$Q/gas_print.in" --periodic --pressure --quiet --threads 3 --checkpoint "$Q/omp.ck" --checkpoint-every 6 > /dev/null 2>&1
if cmp -s "$Q/seq.ck" "$Q/omp.ck"; then pass "periodic checkpoint: seq's and omp's files alike"
else fail "periodic checkpoint: seq's and omp's files" "$(cmp "$Q/seq.ck" "$Q/omp.ck" 2>&1 | head -1)"; fi
./seq "$Q/gas_print.in" --periodic --pressure --quiet > "$Q/ck.ref" 2> "$Q/ck.err"
./omp --resume "$Q/seq.ck" --quiet --threads 2 > "$Q/ck.out" 2> "$Q/ck.out.err"
if tail -n $((3 * 500)) "$Q/ck.ref" | cmp -s - "$Q/ck.out" &&
    [ "$(sed 's/^omp: //' "$Q/ck.out.err")" = "$(sed 's/^seq: //' "$Q/ck.err")" ]; then
    pass "periodic checkpoint: seq's of step 12 resumed by omp, steps 13 to 15 and the whole run's pressure line"
else
    fail "periodic checkpoint: resumed by omp" "$(head -c 300 "$Q/ck.out.err")"
fi
# a checkpoint of format 1 (an earlier build's, of a walled run with --pressure at step 6 of 10)
./seq tests/periodic/walled_v1.in --quiet --pressure > "$Q/v1.ref" 2> "$Q/v1.err"
./seq --resume tests/periodic/walled_v1.ck --quiet > "$Q/v1.out" 2> "$Q/v1.out.err"
if tail -n $((4 * 20)) "$Q/v1.ref" | cmp -s - "$Q/v1.out" && cmp -s "$Q/v1.out.err" "$Q/v1.err"; then
    pass "checkpoint of format 1 resumed as a walled run, its pressure line"
else
    fail "checkpoint of format 1" "$(head -c 300 "$Q/v1.out.err")"
fi
if have_gpu; then
    ./seq "$Q/gas_print.in" --periodic --quiet > "$Q/plain.ref"
    ./seq "$Q/gas_print.in" --periodic --quiet --checkpoint "$Q/plain.ck" --checkpoint-every 6 > /dev/null
    if ./cuda --resume "$Q/plain.ck" --quiet > "$Q/plain.out" 2> "$Q/plain.err" &&
        tail -n $((3 * 500)) "$Q/plain.ref" | cmp -s - "$Q/plain.out"; then
        pass "periodic checkpoint: seq's of step 12 resumed by cuda, steps 13 to 15"
    else
        fail "periodic checkpoint: resumed by cuda" "$(head -c 300 "$Q/plain.err")"
    fi
else
    skip "periodic checkpoint: resumed by cuda" "no GPU"
fi

# ---- random placement: [0, L)^2, no overlaps by the nearest image, the same disks on every thread count ----
printf '3000\n140\n1\n0\nperf\n' > "$Q/place.in"
./seq "$Q/place.in" --periodic --quiet --dump17 > "$Q/place.ref"
bad=$(threads_mismatch "1 3 7" "$Q/place.ref" ./omp "$Q/place.in" --periodic --quiet --dump17)
report=$(head -n 3000 "$Q/place.ref" | tools/measure --periodic "$Q/place.in" -)
if [ -z "$bad" ] && [[ $report == *" overlap_pairs_per_state=0 "* ]] &&
    awk '$3 < 0 || $3 >= 140 || $4 < 0 || $4 >= 140 { exit 1 }' "$Q/place.ref"; then
    pass "periodic placement: 3000 disks at area fraction 0.48 in [0, L), no overlaps by the nearest image, alike on 1, 3, 7 threads"
else
    fail "periodic placement" "$bad $(head -c 200 <<< "$report")"
fi

# ---- tools ----
./tools/gen 2000 --periodic --fraction 0.5 --steps 0 --seed 4 > "$Q/gen.in"
./seq "$Q/gen.in" --periodic --quiet --dump17 2> /dev/null | head -n 2000 > "$Q/gen.state"
report=$(tools/measure --periodic "$Q/gen.in" "$Q/gen.state")
if [[ $report == *" overlap_pairs_per_state=0 "* ]] && awk 'NR > 5 && ($2 < 0 || $2 >= L || $3 < 0 || $3 >= L) { exit 1 }
    NR == 2 { L = $1 }' "$Q/gen.in"; then
    pass "gen --periodic: 2000 disks at area fraction 0.5, centres in [0, L), no overlaps by the nearest image"
else
    fail "gen --periodic" "$(head -c 200 <<< "$report")"
fi
if ./tools/gen 400 --lattice > /dev/null 2> "$Q/gen.err"; then
    fail "gen --lattice 400" "accepted a count without a crystal"
elif grep -q "418 (19 x 22)" "$Q/gen.err"; then
    pass "gen --lattice: a count without a crystal refused, the nearest ones named"
else
    fail "gen --lattice 400" "$(head -c 200 "$Q/gen.err")"
fi
# (speed 0.1: the crystal checked before and after one --exact step, which at speed 1 takes seconds)
./tools/gen 780 --lattice --fraction 0.9 --speed 0.1 --steps 1 --seed 2 > "$Q/lat.in" 2> /dev/null
if awk 'NR > 5 { sx += $4; sy += $5; n++ } END { exit !(n == 780 && sx < 1e-12 && sx > -1e-12 && sy < 1e-12 && sy > -1e-12) }' "$Q/lat.in" &&
    tools/measure --periodic --depth 0 "$Q/lat.in" <(./seq "$Q/lat.in" --periodic --quiet --dump17 --exact) |
    grep -q " overlap_pairs_per_state=0 "; then
    pass "gen --lattice 780 at 0.9: zero total momentum, no overlaps"
else
    fail "gen --lattice 780" "momentum or overlaps"
fi
# measure --periodic sees an overlap across the corner that a walled reading does not
printf '2\n10\n1\n0\nperf\n' > "$Q/corner.in"
printf '0 0 0.25 0.25 0 0\n0 1 9.5 9.5 0 0\n' > "$Q/corner.state"
wrap=$(tools/measure --periodic "$Q/corner.in" "$Q/corner.state" | sed 's/.* overlap_pairs_per_state=\([^ ]*\) .*/\1/')
flat=$(tools/measure "$Q/corner.in" "$Q/corner.state" | sed 's/.* overlap_pairs_per_state=\([^ ]*\) .*/\1/')
if [ "$wrap" = 1 ] && [ "$flat" = 0 ]; then pass "measure --periodic: an overlap across the corner found"
else fail "measure --periodic: an overlap across the corner" "$wrap with --periodic, $flat without"; fi
./seq "$Q/three_cells.in" --periodic --quiet --dump17 > "$Q/tc.out"
if tools/check --dump17 --periodic "$Q/three_cells.in" "$Q/tc.out" && ! tools/check --dump17 "$Q/three_cells.in" "$Q/tc.out" 2> /dev/null; then
    pass "check --periodic: a periodic run's output holds (without it: centres outside [r, L-r])"
else
    fail "check --periodic" "$(tools/check --dump17 --periodic "$Q/three_cells.in" "$Q/tc.out" 2>&1 | head -c 200)"
fi
sed '3s/^0 2 [^ ]*/0 2 9.0/' "$Q/tc.out" > "$Q/tc.bad"
if ! tools/check --dump17 --periodic "$Q/three_cells.in" "$Q/tc.bad" 2> "$Q/chk.err" && grep -q "outside \[0, L)" "$Q/chk.err"; then
    pass "check --periodic: a centre at L refused"
else
    fail "check --periodic: a centre at L" "$(head -c 200 "$Q/chk.err")"
fi
frames=$(tools/xyz --periodic inputs/periodic/edges_print.in outputs/periodic/edges_print.out | grep -c 'pbc="T T F"$')
walled=$(tools/xyz inputs/periodic/edges_print.in outputs/periodic/edges_print.out | grep -c 'pbc="F F F"$')
if [ "$frames" = 21 ] && [ "$walled" = 21 ]; then
    pass "xyz --periodic: pbc=\"T T F\" on each of the 21 frames (pbc=\"F F F\" without it)"
else
    fail "xyz --periodic" "$frames and $walled frames"
fi
