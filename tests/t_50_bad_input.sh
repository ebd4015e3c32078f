# Bad input (SPEC.md 6): each tests/bad/NAME.in, listed in tests/bad/lines.txt with the line its error is
# on, must make every backend exit non-zero with nothing on stdout and exactly one stderr line
# "prog: file:line: what is wrong (what was found)". Then bad command lines, unreadable input and
# write errors (a full disk, a closed stdout, a closed pipe).

for f in tests/bad/*.in; do
    grep -q "^$(basename "$f" .in) " tests/bad/lines.txt || fail "bad/$(basename "$f" .in)" "not in lines.txt"
done
while read -r name line; do
    case $name in '#'* | '') continue ;; esac
    f=tests/bad/$name.in
    for prog in $(backend_list); do
        expect_error "bad/$name $prog" "^$prog: $f:$line: .+ \(.+\)\$" ./$prog "$f"
    done
done < tests/bad/lines.txt

# an error on the very last line of a long print-mode input still comes before any output
awk '{ print } END { print "0 1 2 3" }' inputs/overlapping_print.in > "$TMP/late_error.in"
late=$(($(wc -l < "$TMP/late_error.in")))
for prog in $(backend_list); do
    expect_error "bad/late_error $prog" "^$prog: $TMP/late_error.in:$late: .+ \(.+\)\$" ./$prog "$TMP/late_error.in"
done

for prog in $(backend_list); do
    STDIN_FILE=tests/bad/n_word.in expect_error "bad stdin (no path) $prog" "^$prog: <stdin>:1: .+ \(.+\)\$" ./$prog
    STDIN_FILE=tests/bad/x_nan.in expect_error "bad stdin ('-') $prog" "^$prog: <stdin>:6: .+ \(.+\)\$" ./$prog -
    expect_error "missing file $prog" "^$prog: tests/bad/no_such_file.in: .+ \(.+\)\$" ./$prog tests/bad/no_such_file.in
    expect_error "directory as input $prog" "^$prog: tests/bad: .+ \(.+\)\$" ./$prog tests/bad
    expect_error "unknown option $prog" "^$prog: .*--frobnicate" ./$prog tests/hard/corners.in --frobnicate
    expect_error "--seed without value $prog" "^$prog: .*--seed" ./$prog tests/hard/corners.in --seed
    expect_error "--seed not a number $prog" "^$prog: .*--seed" ./$prog tests/hard/corners.in --seed 1x
    expect_error "two inputs $prog" "^$prog: " ./$prog tests/hard/corners.in tests/hard/corners.in
    expect_error "write to /dev/full $prog" "^$prog: .*write" sh -c "./$prog tests/hard/corners.in --quiet > /dev/full"
    expect_error "--help to /dev/full $prog" "^$prog: .*write" sh -c "./$prog --help > /dev/full"
    expect_error "closed stdout $prog" "^$prog: .*write" sh -c "./$prog tests/hard/corners.in --quiet >&-"
    # 380 kB of output into a pipe whose reader has gone
    ./$prog inputs/random_300_print.in --quiet 2> "$TMP/err" | head -c 10 > /dev/null
    rc=${PIPESTATUS[0]}
    if [ "$rc" -ne 0 ] && grep -q "write" "$TMP/err"; then
        pass "closed pipe $prog"
    else
        fail "closed pipe $prog" "exit $rc: $(head -c 200 "$TMP/err")"
    fi
done
expect_error "omp --threads 0" "^omp: .*--threads" ./omp tests/hard/corners.in --threads 0
expect_error "seq has no --threads" "^seq: .*--threads" ./seq tests/hard/corners.in --threads 2
expect_error "omp --keep 65" "^omp: .*--keep" ./omp tests/hard/corners.in --keep 65
expect_error "omp --lanes 2" "^omp: .*--lanes" ./omp tests/hard/corners.in --lanes 2
expect_error "seq has no --keep" "^seq: .*--keep" ./seq tests/hard/corners.in --keep 8
