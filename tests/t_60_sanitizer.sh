# The hard cases, a generated scene and some bad inputs under address and undefined-behaviour checks
# (make seq_san): same bytes, no sanitizer report.
if [ ! -x ./seq_san ]; then
    skip "sanitizer" "seq_san not built"
else
    for f in tests/hard/*.in; do
        b=$(basename "$f" .in)
        [ -f "tests/hard/$b.out" ] || continue
        same_bytes "sanitizer hard/$b" "tests/hard/$b.out" ./seq_san "$f" --quiet
    done
    same_bytes "sanitizer golden/random_300_print" outputs/random_300_print.out ./seq_san inputs/random_300_print.in --quiet
    for b in empty nul_byte index_duplicate missing_particle error_on_last_line_without_newline placement_impossible; do
        ./seq_san "tests/bad/$b.in" > "$TMP/out" 2> "$TMP/err"
        rc=$?
        if [ "$rc" -eq 1 ] && [ ! -s "$TMP/out" ] && [ "$(wc -l < "$TMP/err")" -eq 1 ]; then
            pass "sanitizer bad/$b"
        else
            fail "sanitizer bad/$b" "exit $rc: $(head -c 300 "$TMP/err")"
        fi
    done
fi
