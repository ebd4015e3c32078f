# Accepted input (SPEC.md 1): CR LF, blank and whitespace-only lines, tabs, trailing whitespace, leading
# '+', other spellings of the same reals, particle lines in any order and no final newline all give the
# bytes of the clean file, on every backend. Also stdin ('-' and no path), option order, --help and
# the seeded placement.
clean=tests/cases/example_dense_print.in
clean_out=tests/cases/example_dense_print.out

accept() { # NAME FILTER: the clean input through FILTER must give the clean output
    sh -c "$2" < "$clean" > "$TMP/$1.in"
    if cmp -s "$TMP/$1.in" "$clean"; then
        fail "accept/$1" "the filter changed nothing"
        return
    fi
    same_bytes "accept/$1 seq" "$clean_out" ./seq "$TMP/$1.in" --quiet
    same_bytes "accept/$1 omp" "$clean_out" ./omp "$TMP/$1.in" --quiet --threads 3
    if have_gpu; then same_bytes "accept/$1 cuda" "$clean_out" ./cuda "$TMP/$1.in" --quiet; fi
}
plus='{ for (k = 1; k <= NF; k++) if ($k ~ /^[0-9.]/) $k = "+" $k; print }'
accept crlf "sed 's/\$/\r/'"
accept blank_lines "awk '{ print \"\"; print \" \t \"; print } END { print \"\"; print \"\" }'"
accept tabs "tr ' ' '\t'"
accept trailing_whitespace "sed 's/\$/ \t /'"
accept leading_whitespace "sed 's/^/  /'"
accept leading_plus "awk '$plus'"
accept no_final_newline "head -c -1"
reverse='NR <= 5 { print; next } { line[++n] = $0 } END { while (n) print line[n--] }'
accept reversed_particles "awk '$reverse'"
accept shuffled_particles "awk 'NR <= 5 { print; fflush(); next } { print | \"sort -k3,3\" }'"
accept other_spellings "awk 'NR == 1 { \$1 = \"060\" } NR == 2 { \$1 = \"0.4E+2\" } NR == 3 { \$1 = \"1.000\" } NR == 4 { \$1 = \"+40\" } 1'"
accept everything_at_once "awk '$reverse' | awk '$plus' | awk '{ print \"\"; print } END { printf \"\t\" }' | sed 's/\$/ \r/'"

same_bytes "stdin without a path" "$clean_out" sh -c "./seq --quiet < $clean"
same_bytes "stdin as '-'" "$clean_out" sh -c "./seq - --quiet < $clean"
same_bytes "stdin as '-' omp" "$clean_out" sh -c "./omp --quiet - --threads 2 < $clean"
same_bytes "options before the path" "$clean_out" ./seq --quiet "$clean"

for prog in seq omp; do
    if ./$prog --help > "$TMP/out" 2> "$TMP/err" && [ ! -s "$TMP/err" ] && grep -q "^usage: $prog" "$TMP/out" &&
        grep -q -- "--seed" "$TMP/out" && grep -q -- "--dump17" "$TMP/out"; then
        pass "--help $prog"
    else
        fail "--help $prog"
    fi
done
if ./omp --help | grep -q -- "--threads"; then pass "--help omp lists --threads"; else fail "--help omp lists --threads"; fi

# Placement is seeded, done once in io.c: the default is --seed 1, another seed gives other disks, and
# every backend sees the same ones.
gen=inputs/random_300_print.in
same_bytes "seed: default is --seed 1" "outputs/random_300_print.out" ./seq "$gen" --quiet --seed 1
./seq "$gen" --quiet --seed 5 > "$TMP/seed5"
if cmp -s "$TMP/seed5" outputs/random_300_print.out; then fail "seed: --seed 5 differs"; else pass "seed: --seed 5 differs"; fi
same_bytes "seed: --seed 5 omp" "$TMP/seed5" ./omp "$gen" --quiet --seed 5 --threads 3
if have_gpu; then same_bytes "seed: --seed 5 cuda" "$TMP/seed5" ./cuda "$gen" --quiet --seed 5; fi
# generated disks start inside the box, apart, with speeds between L/(8r) and L/4
./seq "$gen" --quiet --dump17 --seed 5 > "$TMP/seed5.17"
if awk -v L=3000 -v r=1 'NR == 1 { n = 0 } $1 == 0 && NF == 6 {
        x[n] = $3; y[n] = $4; s = sqrt($5 * $5 + $6 * $6); n++
        if ($3 < r || $3 > L - r || $4 < r || $4 > L - r) bad = bad " outside"
        lo = L / (8 * r); hi = L / 4; if (lo > hi) { t = lo; lo = hi; hi = t }
        if (s < lo * (1 - 1e-12) || s > hi * (1 + 1e-12)) bad = bad " speed " s }
    END { for (i = 0; i < n; i++) for (j = i + 1; j < n; j++)
              if ((x[i] - x[j]) ^ 2 + (y[i] - y[j]) ^ 2 < 4 * r * r) bad = bad " overlap"
          if (bad != "") { print bad; exit 1 } }' "$TMP/seed5.17"; then
    pass "seed: generated disks inside, apart, speeds in range"
else
    fail "seed: generated disks inside, apart, speeds in range"
fi
