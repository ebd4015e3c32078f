# Hard cases (tests/hard/README.md derives each expected output by hand): exact ties, corners, grazes,
# overlapped and coincident starts, stops at walls, t = 1, extreme sizes, S = 0. A case with NAME.out
# must match it byte for byte; one with NAME.counts must end with exactly those collision counts.
for f in tests/hard/*.in; do
    b=$(basename "$f" .in)
    if [ -f "tests/hard/$b.out" ]; then
        on_backends "hard/$b" "tests/hard/$b.out" "$f"
        continue
    fi
    n=$(wc -l < "tests/hard/$b.counts")
    for prog in $(backend_list) "omp --threads 3"; do
        if ./$prog "$f" --quiet > "$TMP/out" 2> "$TMP/err" &&
            tail -n "$n" "$TMP/out" | awk '{ print $7, $8 }' | cmp -s - "tests/hard/$b.counts"; then
            pass "hard/$b $prog counts"
        else
            fail "hard/$b $prog counts" "$(tail -n "$n" "$TMP/out" | awk '{ print $7, $8 }' | tr '\n' ' ')"
        fi
    done
done
# The expected outputs are what the exact-rational derivation gives; and the same code run on plain
# doubles (an implementation of SPEC.md 3 independent of common.h) reproduces the worked examples and a
# golden output. Python is optional; the derivations (exact rationals, some 15 s) check the expected
# files rather than the programs, so the quick suite leaves them out.
if ! all_suite; then
    :
elif command -v python3 >/dev/null 2>&1; then
    for f in tests/hard/*.in; do
        b=$(basename "$f" .in)
        [ -f "tests/hard/$b.out" ] || continue
        same_bytes "hard/$b derivation" "tests/hard/$b.out" python3 tests/hard/derive.py "$f"
    done
    for f in tests/cases/*.in inputs/overlapping_print.in; do
        b=$(basename "$f" .in)
        expected=${f%.in}.out
        [ -f "$expected" ] || expected=outputs/$b.out
        same_bytes "independent model $b" "$expected" python3 tests/hard/derive.py --inexact "$f"
    done
    for f in tests/hard/*.counts; do
        ./seq "${f%.counts}.in" --quiet > "$TMP/seq.out"
        same_bytes "independent model $(basename "$f" .counts) agrees with seq" "$TMP/seq.out" \
            python3 tests/hard/derive.py --inexact "${f%.counts}.in"
    done
else
    skip "hard derivations and independent model" "no python3"
fi
