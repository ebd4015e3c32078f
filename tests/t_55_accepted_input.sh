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

# Every real of a particle line read as strtod reads it (correctly rounded), whichever way the line goes
# (input.c: read_line_fast takes well-formed lines in one pass, any other goes through split_line and
# io_parse_real): 20000 random lines of 1 to 22 digits, with and without a point, signs, leading zeros,
# exponents, tabs and carriage returns, read by seq and printed back with --dump17 (%.17g), against
# Python's float() of the same text.
if command -v python3 > /dev/null 2>&1; then
    python3 - "$TMP/reals.in" "$TMP/reals.expected" <<'PY'
import random, sys
random.seed(55)
n, L = 20000, 1000000
def real(lo_digits, hi_digits, signed):
    r = random.random()
    whole = str(random.randint(0, 10 ** random.randint(lo_digits, hi_digits) - 1))
    if r < 0.1: whole = "0" * random.randint(1, 3) + whole
    frac = "".join(random.choice("0123456789") for _ in range(random.randint(0, 22)))
    s = whole + ("." + frac if frac or random.random() < 0.2 else "")
    if random.random() < 0.05: s = s + "e" + str(random.randint(-3, 2))
    if signed and random.random() < 0.5: s = "-" + s
    elif random.random() < 0.03: s = "+" + s
    return s
lines, out = [], []
for i in range(n):
    while True:
        x, y = real(1, 5, False), real(1, 5, False)
        if 1 <= float(x) <= L - 1 and 1 <= float(y) <= L - 1: break
    vx, vy = real(0, 8, True), real(0, 8, True)
    sep = lambda: random.choice([" ", " ", " ", "\t", "  "])
    lines.append(f"{i}{sep()}{x}{sep()}{y}{sep()}{vx}{sep()}{vy}" + ("\r" if random.random() < 0.05 else ""))
    out.append("0 %d %.17g %.17g %.17g %.17g" % (i, float(x), float(y), float(vx), float(vy)))
open(sys.argv[1], "w").write(f"{n}\n{L}\n1\n0\nperf\n" + "\n".join(lines) + "\n")
open(sys.argv[2], "w").write("\n".join(out) + "\n")
PY
    if ./seq "$TMP/reals.in" --quiet --dump17 > "$TMP/reals.out" 2> "$TMP/err"; then
        head -n 20000 "$TMP/reals.out" > "$TMP/reals.step0"
        if cmp -s "$TMP/reals.step0" "$TMP/reals.expected"; then
            pass "accept: 20000 random lines' reals read as strtod reads them"
        else
            fail "accept: 20000 random lines' reals read as strtod reads them" \
                "$(diff "$TMP/reals.step0" "$TMP/reals.expected" | head -3 | tr '\n' ' ')"
        fi
    else
        fail "accept: 20000 random lines' reals read as strtod reads them" "$(head -c 200 "$TMP/err")"
    fi
else
    skip "accept: 20000 random lines' reals read as strtod reads them" "no python3"
fi
