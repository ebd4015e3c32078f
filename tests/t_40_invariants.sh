# Invariants (tools/check.c) on the output of every bundled input, case and hard case: shape of every
# line, finite reals, centres in [r, L-r], p + w <= S; with --dump17 (exact reals) also kinetic energy
# kept to a few ulps per collision and no more steps that differ from a plain move (x += vx) than
# events p + w. The final lines of print and perf mode are identical, and omp prints the same exact
# reals as seq. Then the checker itself must reject broken outputs.
check_output() { # NAME INPUT OUTPUT [--dump17]
    local msg
    if msg=$(./tools/check ${4:-} "$2" "$3" 2>&1); then pass "$1"; else fail "$1" "$msg"; fi
}

# the quick suite leaves out the bundled scene that takes seq seconds (t_20 holds it to its golden output)
slow_seq() { ! all_suite && [ "$1" = inputs/random_1000_perf.in ]; }

for f in inputs/*.in tests/cases/*.in tests/hard/*.in; do
    slow_seq "$f" && continue
    name="invariants/$(basename "$(dirname "$f")")/$(basename "$f" .in)"
    if ! ./seq "$f" --quiet --dump17 > "$TMP/d17" 2> "$TMP/err"; then
        fail "$name" "seq failed: $(head -c 300 "$TMP/err")"
        continue
    fi
    check_output "$name dump17" "$f" "$TMP/d17" --dump17
    ./seq "$f" --quiet > "$TMP/fixed" 2> /dev/null
    check_output "$name %.8f" "$f" "$TMP/fixed"
    # the same input in the other mode
    awk 'NF && ++k == 5 { $1 = ($1 == "print") ? "perf" : "print" } 1' "$f" > "$TMP/other.in"
    ./seq "$TMP/other.in" --quiet > "$TMP/other" 2> /dev/null
    check_output "$name other mode" "$TMP/other.in" "$TMP/other"
    n=$(awk 'NF { print $1; exit }' "$f")
    if cmp -s <(tail -n "$n" "$TMP/fixed") <(tail -n "$n" "$TMP/other"); then
        pass "$name print and perf end alike"
    else
        fail "$name print and perf end alike"
    fi
done

for f in inputs/*.in; do
    slow_seq "$f" && continue
    ./seq "$f" --quiet --dump17 > "$TMP/d17" 2> /dev/null
    same_bytes "invariants/$(basename "$f" .in) omp dump17" "$TMP/d17" ./omp "$f" --quiet --dump17 --threads 3
done

# The checker must notice each kind of damage.
ref=tests/hard/pair_then_wall.in
./seq "$ref" --quiet --dump17 > "$TMP/good"
check_rejects() { # WHAT FILTER
    sh -c "$2" < "$TMP/good" > "$TMP/bad"
    if ./tools/check --dump17 "$ref" "$TMP/bad" 2> /dev/null; then
        fail "check rejects $1"
    else
        pass "check rejects $1"
    fi
}
check_output "check accepts the intact output" "$ref" "$TMP/good" --dump17
check_rejects "a missing line" "sed 3d"
check_rejects "an extra line" "sed 3p"
check_rejects "a missing final newline" "head -c -1"
check_rejects "a centre outside [r, L-r]" "awk 'NR == 3 { \$3 = \"15.5\" } 1'"
check_rejects "a centre moved without an event" "awk 'NR == 4 { \$3 = \"12.5\" } 1'"
check_rejects "a changed kinetic energy" "awk 'NR == 6 { \$5 = \"0.5\" } 1'"
check_rejects "a nan" "awk 'NR == 2 { \$4 = \"nan\" } 1'"
check_rejects "p + w > S" "awk 'NR == 5 { \$8 = \"2\" } 1'"
check_rejects "an odd sum of p" "awk 'NR == 5 { \$7 = \"0\" } 1'"
check_rejects "a wrong step number" "awk 'NR == 3 { \$1 = \"2\" } 1'"
check_rejects "a wrong index" "awk 'NR == 4 { \$2 = \"0\" } 1'"
check_rejects "a double space" "sed '2s/ /  /'"
check_rejects "a missing count" "awk 'NR == 6 { \$8 = \"\" } 1'"
