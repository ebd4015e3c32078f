# --exact (exact.h): the event-driven model, every collision in time order.
# - hand-derived cases (tests/exact/README.md) on seq and omp at 1, 2, 3 and 7 threads, double and float;
# - omp --exact against seq --exact, byte for byte, on generated scenes (fast, slow, dense, dilute,
#   overlapping; print and perf) at 1, 2, 3 and 7 threads, in both builds;
# - the physics: kinetic energy kept to rounding (relative drift < 1e-12 over 300 steps), no overlaps
#   on non-overlapping starts (tools/check --exact, which must also catch the overlaps of SPEC.md's step);
# - omp --exact --check (every window against all pairs) on scenes of thousands of disks; seq_san;
# - the parallel event loop (omp_exact.c: strips, taint times, bands near the cuts, windows stopped and
#   run again): scenes that load the cuts (a gas at area fraction 0.5, fast disks crossing strips, 150
#   disks in strips on 16 threads, a lattice whose collisions outrun the velocity bound) at 1, 2, 3, 7
#   and 16 threads in both builds; seq's event count, --pressure line and checkpoint file; a smaller
#   team than asked for (OMP_DYNAMIC);
# - option handling: cuda rejects --exact, --exact with --substeps is an error.
X=$TMP/exact
mkdir -p "$X"

for f in tests/exact/*.out; do
    b=$(basename "$f" .out)
    f=${f%.out}.in
    on_backends_exact() {
        local prog t
        for prog in seq seq_f32; do
            same_bytes "exact/$b $prog" "tests/exact/$b.out" ./$prog "$f" --exact --quiet
        done
        for prog in omp omp_f32; do
            for t in 1 2 3 7; do
                same_bytes "exact/$b $prog $t threads" "tests/exact/$b.out" ./$prog "$f" --exact --quiet \
                    --threads "$t"
            done
        done
    }
    on_backends_exact
done

# A lone disk with speeds unrelated to the box, 50 steps, 37 wall collisions: against the closed form
# (unfold each axis: u = (c0 - lo) + v t, fold with period 2 (hi - lo)), positions within 1e-9,
# velocity signs and the wall count exact.
closed_form() { # prints: worst position error, velocity mismatches, expected w, printed w
    awk 'function floor(a,   f) { f = int(a); return f > a ? f - 1 : f }
         function fold(c0, v, t,   u, m) { u = (c0 - 1) + v * t; m = u - 16 * floor(u / 16)
                                           pos = 1 + (m <= 8 ? m : 16 - m); vel = m < 8 ? v : -v }
         function err(a, b) { return a > b ? a - b : b - a }
         BEGIN { vx = 3.14159265; vy = -2.71828183 }
         { fold(5, vx, $1); if (err($3, pos) > worst) worst = err($3, pos); bad += sprintf("%.8f", vel) != $5
           fold(5, vy, $1); if (err($4, pos) > worst) worst = err($4, pos); bad += sprintf("%.8f", vel) != $6
           if (NF == 8) { w = floor((4 + vx * 50) / 8) - floor((4 + vy * 50) / 8); got = $8 } }
         END { printf "%g %d %d %d\n", worst, bad, w, got }' "$1"
}
for prog in seq "omp --threads 2"; do
    # shellcheck disable=SC2086
    ./$prog tests/exact/closed_form.in --exact --quiet > "$X/closed.out" 2> "$X/err"
    read -r worst bad w got < <(closed_form "$X/closed.out")
    if [ "$bad" = 0 ] && [ "$w" = 37 ] && [ "$got" = 37 ] && awk -v e="$worst" 'BEGIN { exit !(e < 1e-9) }'; then
        pass "exact/closed_form $prog: 50 steps within $worst of the closed form, w = 37"
    else
        fail "exact/closed_form $prog" "error $worst, $bad velocity mismatches, w = $got (expected $w)"
    fi
done

# name and tools/gen arguments, one scene a line
exact_scenes() {
    cat <<'SCENES'
slow_print       400 --speed 0.5 --steps 30 --mode print
fast_print       300 --assignment --L 300 --steps 15 --mode print
fast_dilute      300 --assignment --L 3000 --steps 15
dense_print      600 --fraction 0.45 --speed 0.3 --steps 20 --mode print
dense_fast       500 --r 5 --fraction 0.4 --speed 4 --steps 15
dilute           200 --fraction 0.01 --speed 3 --steps 40 --mode print
overlap_print    300 --fraction 0.5 --overlap --speed 1 --steps 20 --mode print
overlap_fast     200 --overlap --assignment --L 100 --steps 15 --mode print
tiny_radius      300 --r 0.001 --fraction 0.1 --speed 2 --steps 20 --mode print
mid_dense        2000 --fraction 0.4 --speed 1 --steps 4
overlap_deep     3000 --fraction 3 --overlap --speed 0.3 --steps 3 --mode print
SCENES
}

exact_compare() { # name input suffix [extra options]; EXACT_THREADS: the thread counts
    local name=$1 in=$2 suf=$3 bad threads=${EXACT_THREADS:-1 2 3 7}
    shift 3
    if ! ./seq$suf "$in" --exact --quiet "$@" > "$X/$name.ref" 2> "$X/err"; then
        fail "exact/$name seq$suf" "$(head -c 300 "$X/err")"
        return
    fi
    bad=$(threads_mismatch "$threads" "$X/$name.ref" ./omp$suf "$in" --exact --quiet "$@")
    if [ -z "$bad" ]; then
        pass "exact/$name omp$suf --exact same bytes as seq$suf at $threads threads"
    else
        fail "exact/$name omp$suf --exact" "$bad"
    fi
}

# (the quick suite: no scene above 2000 disks, the float build up to 600)
while read -r name args; do
    n=${args%% *}
    if ! all_suite && [ "$n" -gt 2000 ]; then continue; fi
    # shellcheck disable=SC2086
    tools/gen $args > "$X/$name.in"
    exact_compare "$name" "$X/$name.in" ""
    if all_suite || [ "$n" -le 600 ]; then exact_compare "$name" "$X/$name.in" _f32; fi
done < <(exact_scenes)
printf '300\n400\n1\n10\nprint\n' > "$X/random.in"
exact_compare random "$X/random.in" "" --seed 7

# The parallel event loop (omp_exact.c): each window's strips run their events concurrently and the
# disks near the cuts (tainted) run in bands after them. Scenes that load the cuts: a gas at area
# fraction 0.5, fast disks that cross strips within a window, 150 disks cut into strips on up to 16
# threads, and a lattice of diagonal velocities whose collisions outrun the velocity bound (the window
# stops, runs again up to just before the stop, and the instant after it runs sequentially), in both
# builds at 1, 2, 3, 7 and 16 threads (more threads than cores).
tools/gen 1000 --fraction 0.5 --speed 1 --steps 5 > "$X/half.in"
tools/gen 1000 --fraction 0.3 --speed 0.5 --fast 0.01 --fast-speed 0.1 --steps 4 > "$X/crossing.in"
tools/gen 150 --fraction 0.3 --speed 1 --steps 20 --mode print > "$X/few.in"
diag_lattice 30 3 > "$X/lattice.in"
for name in half crossing few lattice; do
    for suf in "" _f32; do
        if [ "$suf" = _f32 ] && ! all_suite && [ "$name" != lattice ]; then continue; fi
        EXACT_THREADS="1 2 3 7 16" exact_compare "$name" "$X/$name.in" "$suf"
    done
done
./omp "$X/lattice.in" --exact --stats --quiet --threads 3 > /dev/null 2> "$X/lattice.err"
if grep -Eq ' [1-9][0-9]* parallel tries stopped' "$X/lattice.err"; then
    pass "exact/lattice stops a parallel window and runs it again"
else
    fail "exact/lattice stops a parallel window" "$(grep 'exact:' "$X/lattice.err" | head -c 300)"
fi
# On the gas, at each thread count: seq's event count, split by --stats into the strips' events, the
# bands' (some) and those of sequential windows; seq's --pressure line (each disk's impulses added in
# its own event order); seq's checkpoint file (the last partners included); and under OMP_DYNAMIC, a
# team smaller than asked for.
half_run() { # PROGRAM [OPTIONS]: stdout, stderr and checkpoint into $X/half.run.*
    "$@" "$X/half.in" --exact --stats --pressure --quiet --checkpoint "$X/half.run.ck" --checkpoint-every 2 \
        > "$X/half.run.out" 2> "$X/half.run.err"
}
pressure_of() { sed -n 's/^[a-z_0-9]*: \(pressure: .*\)/\1/p' "$1"; }
half_run ./seq
for f in out err ck; do mv "$X/half.run.$f" "$X/half.seq.$f"; done
for t in 1 2 7 16 4:OMP_DYNAMIC=true; do
    if [ "${t#*:}" != "$t" ]; then half_run env "${t#*:}" ./omp --threads "${t%%:*}"; else half_run ./omp --threads "$t"; fi
    split=$(exact_split "$X/half.run.err")
    read -r in_strips in_bands in_seq <<< "$split"
    total=$(exact_events "$X/half.seq.err")
    if ! cmp -s "$X/half.run.out" "$X/half.seq.out"; then
        fail "exact/half omp --threads $t: output differs from seq's"
    elif [ "$(exact_events "$X/half.run.err")" != "$total" ] || [ "$((in_strips + in_bands + in_seq))" != "$total" ] ||
        { [ "${t%%:*}" -gt 1 ] && [ "$in_bands" = 0 ]; }; then
        fail "exact/half omp --threads $t --stats" "seq: $total events; omp: $(grep -h 'events' "$X/half.run.err" | head -c 300)"
    elif [ "$(pressure_of "$X/half.run.err")" != "$(pressure_of "$X/half.seq.err")" ] || [ -z "$(pressure_of "$X/half.seq.err")" ]; then
        fail "exact/half omp --threads $t --pressure" "$(pressure_of "$X/half.run.err") against seq's $(pressure_of "$X/half.seq.err")"
    elif ! cmp -s "$X/half.run.ck" "$X/half.seq.ck"; then
        fail "exact/half omp --threads $t --checkpoint" "the file differs from seq's"
    else
        pass "exact/half omp --threads $t: seq's bytes, pressure, checkpoint and $total events ($in_strips in strips, $in_bands in bands, $in_seq sequential)"
    fi
done

# Energy over 300 steps of a dense gas (thousands of collisions per step): relative drift < 1e-12.
tools/gen 400 --fraction 0.3 --speed 1 --steps 300 > "$X/energy.in"
if ./omp "$X/energy.in" --exact --dump17 --quiet --threads 2 > "$X/energy.out" 2> "$X/err"; then
    drift=$(awk 'NF == 6 && $1 == 0 { e0 += $5 * $5 + $6 * $6 } NF == 8 { e1 += $5 * $5 + $6 * $6 }
                 END { d = (e1 - e0) / e0; if (d < 0) d = -d; printf "%.3g", d }' "$X/energy.out")
    if awk -v d="$drift" 'BEGIN { exit !(d < 1e-12) }'; then
        pass "exact/energy relative drift $drift < 1e-12 over 300 steps"
    else
        fail "exact/energy" "relative drift $drift"
    fi
else
    fail "exact/energy" "$(head -c 300 "$X/err")"
fi

# No overlaps (by more than rounding) and energy per collision on non-overlapping starts; the checker
# must see the overlaps that SPEC.md's one-collision step leaves behind.
for name in slow_print dense_print dilute fast_print tiny_radius; do
    ./seq "$X/$name.in" --exact --dump17 --quiet > "$X/d17" 2> /dev/null
    if msg=$(tools/check --dump17 --exact "$X/$name.in" "$X/d17" 2>&1); then
        pass "exact/$name invariants (no overlaps, energy, shape)"
    else
        fail "exact/$name invariants" "$msg"
    fi
done
./seq "$X/dense_print.in" --dump17 --quiet > "$X/d17" 2> /dev/null
if tools/check --dump17 --exact "$X/dense_print.in" "$X/d17" 2> /dev/null; then
    fail "exact/check sees the overlaps of the default step"
else
    pass "exact/check sees the overlaps of the default step"
fi

# omp --exact --check: after every window, all pairs must show no event the grid missed (the quick
# suite: two of the scenes at 2 threads; the whole suite at 7 too, more strips).
check_scenes=("2000 --fraction 0.4 --speed 1 --steps 3" "1500 --r 1e-6 --L 1 --speed 1e5 --steps 2")
all_suite && check_scenes+=("1500 --assignment --L 1500 --steps 2" "1500 --fraction 0.7 --overlap --speed 2 --steps 2"
                            "1500 --fraction 0.5 --speed 1 --steps 3")
for args in "${check_scenes[@]}"; do
    # shellcheck disable=SC2086
    tools/gen $args > "$X/check.in"
    for prog in omp omp_f32; do
        for t in 2 $(all_suite && echo 7); do
            if ./$prog "$X/check.in" --exact --check --quiet --threads $t > /dev/null 2> "$X/err"; then
                pass "exact/$prog --check --threads $t: $args"
            else
                fail "exact/$prog --check --threads $t: $args" "$(head -c 300 "$X/err")"
            fi
        done
    done
done

# seq under the address and undefined-behaviour sanitizers (built by make test)
if [ -x ./seq_san ]; then
    for f in tests/exact/*.in "$X/overlap_print.in"; do
        [ -f "$f" ] || continue
        if ./seq_san "$f" --exact --quiet > "$X/out" 2> "$X/err" && ./seq "$f" --exact --quiet | cmp -s - "$X/out"; then
            pass "exact/sanitizer $(basename "$f" .in)"
        else
            fail "exact/sanitizer $(basename "$f" .in)" "$(head -c 300 "$X/err")"
        fi
    done
else
    skip "exact/sanitizer" "seq_san not built"
fi

# Options: backends without --exact reject it before any output.
if [ -x ./cuda ]; then
    expect_error "exact/cuda rejects --exact" "--exact is not supported" ./cuda tests/exact/walls.in --exact
else
    skip "exact/cuda rejects --exact" "cuda not built"
fi
for prog in seq omp seq_f32 omp_f32; do
    expect_error "exact/$prog rejects --exact --substeps" "exclude each other" \
        ./$prog tests/exact/walls.in --exact --substeps 2
done

# A step that could not be run event by event (speeds up to L/(8r) = 1e99 in a box of 1e50) is refused
# before any output.
for prog in seq omp; do
    expect_error "exact/$prog refuses 1e49 wall collisions per step" "would hit the walls" \
        ./$prog inputs/extreme_large_box.in --exact --quiet
done
# the same refusal when step 0 alone would overflow the output buffer (200000 lines, over 8 MB): still
# nothing on stdout
printf '200000\n1\n1e-8\n1\nperf\n' > "$X/fast_many.in"
for prog in seq omp; do
    expect_error "exact/$prog refuses 200000 too-fast disks before step 0" "would hit the walls" \
        ./$prog "$X/fast_many.in" --exact --quiet
done

# --pressure: the walls case has 12 reflections of |vx| = 32 and one of |vy| = 2, so the impulse is
# 12 * 64 + 4 = 772 over 3 time units on 4 walls of length 10: P = 772 / 120. omp adds the same per-disk
# sums in the same order as seq on a generated scene.
for prog in seq "omp --threads 3" seq_f32 "omp_f32 --threads 2"; do
    # shellcheck disable=SC2086
    if ./$prog tests/exact/walls.in --exact --pressure --quiet > /dev/null 2> "$X/err" &&
        grep -q "wall impulse 772 over 3 time units on 4 walls of length 10: P = 6.43333333333333" "$X/err"; then
        pass "exact/walls $prog --pressure"
    else
        fail "exact/walls $prog --pressure" "$(head -c 300 "$X/err")"
    fi
done
for suf in "" _f32; do
    ./seq$suf "$X/dense_fast.in" --exact --pressure --quiet > /dev/null 2> "$X/p.ref"
    bad=""
    for t in 1 2 3 7; do
        ./omp$suf "$X/dense_fast.in" --exact --pressure --quiet --threads $t > /dev/null 2> "$X/p.out"
        sed "s/^omp/seq/" "$X/p.out" | cmp -s - "$X/p.ref" || bad="$bad $t"
    done
    if [ -z "$bad" ] && grep -q "pressure: wall impulse" "$X/p.ref"; then
        pass "exact/dense_fast omp$suf --pressure same as seq$suf at 1 2 3 7 threads"
    else
        fail "exact/dense_fast omp$suf --pressure" "differs at$bad: $(head -c 200 "$X/p.ref")"
    fi
done
