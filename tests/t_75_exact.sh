# --exact (exact.h): the event-driven model, every collision in time order.
# - hand-derived cases (tests/exact/README.md) on seq and omp at 1, 2, 3 and 7 threads, double and float;
# - omp --exact against seq --exact, byte for byte, on generated scenes (fast, slow, dense, dilute,
#   overlapping; print and perf) at 1, 2, 3 and 7 threads, in both builds;
# - the physics: kinetic energy kept to rounding (relative drift < 1e-12 over 300 steps), no overlaps
#   on non-overlapping starts (tools/check --exact, which must also catch the overlaps of SPEC.md's step);
# - option handling: cuda rejects --exact, --exact with --substeps is an error.
X=$TMP/exact
mkdir -p "$X"

for f in tests/exact/*.in; do
    b=$(basename "$f" .in)
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
SCENES
}

exact_compare() { # name input suffix [extra options]
    local name=$1 in=$2 suf=$3 t bad=""
    shift 3
    if ! ./seq$suf "$in" --exact --quiet "$@" > "$X/$name.ref" 2> "$X/err"; then
        fail "exact/$name seq$suf" "$(head -c 300 "$X/err")"
        return
    fi
    for t in 1 2 3 7; do
        if ! ./omp$suf "$in" --exact --quiet --threads "$t" "$@" > "$X/out" 2> "$X/err"; then
            bad="$bad $t:exit($(head -c 200 "$X/err"))"
        elif ! cmp -s "$X/out" "$X/$name.ref"; then
            bad="$bad $t:differs"
        fi
    done
    if [ -z "$bad" ]; then
        pass "exact/$name omp$suf --exact same bytes as seq$suf at 1 2 3 7 threads"
    else
        fail "exact/$name omp$suf --exact" "$bad"
    fi
}

while read -r name args; do
    # shellcheck disable=SC2086
    tools/gen $args > "$X/$name.in"
    exact_compare "$name" "$X/$name.in" ""
    exact_compare "$name" "$X/$name.in" _f32
done < <(exact_scenes)
printf '300\n400\n1\n10\nprint\n' > "$X/random.in"
exact_compare random "$X/random.in" "" --seed 7

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

# Options: backends without --exact reject it before any output.
if [ -x ./cuda ]; then
    if ./cuda tests/exact/walls.in --exact > "$X/out" 2> "$X/err"; then
        fail "exact/cuda rejects --exact" "exit 0"
    elif [ -s "$X/out" ] || ! grep -q -- "--exact is not available" "$X/err"; then
        fail "exact/cuda rejects --exact" "$(head -c 300 "$X/err")"
    else
        pass "exact/cuda rejects --exact"
    fi
else
    skip "exact/cuda rejects --exact" "cuda not built"
fi
