# The accuracy study's parts: tools/measure on hand-made outputs whose answers are worked out below;
# --substeps 1 is the SPEC.md step byte for byte; --substeps K > 1 and --pressure give the same bytes
# (stdout and the pressure line) in seq and omp at any thread count, and so does --exact --pressure;
# the pressure of a disk bouncing off a wall, by hand; ./bench.sh accuracy --quick writes a well-formed
# CSV with every rung, --exact included.
A=$TMP/accuracy
mkdir -p "$A"

# ---- tools/measure on outputs with known answers ------------------------------------------------
# measure_expect NAME INPUT OUTPUT "key=value ..." [measure options]: every listed key has that value
# (numbers compared to 1e-9 relative).
measure_expect() {
    local name=$1 in=$2 out=$3 want=$4 got bad
    shift 4
    if ! got=$(./tools/measure "$@" "$in" "$out" 2>&1); then
        fail "measure/$name" "exit status $?: $got"
        return
    fi
    bad=$(awk -v got="$got" -v want="$want" 'BEGIN {
        n = split(got, g, " "); for (k = 1; k <= n; k++) { split(g[k], kv, "="); have[kv[1]] = kv[2] }
        n = split(want, w, " ")
        for (k = 1; k <= n; k++) {
            split(w[k], kv, "=")
            if (!(kv[1] in have)) { print "no " kv[1]; exit }
            a = have[kv[1]]; b = kv[2]
            if (a == b) continue
            if (b ~ /nan/ || a ~ /nan/) { print kv[1] "=" a ", expected " b; exit }
            d = a - b; if (d < 0) d = -d; s = b < 0 ? -b : b
            if (d > 1e-9 * s + 1e-300) { print kv[1] "=" a ", expected " b; exit }
        }
    }')
    if [ -z "$bad" ]; then pass "measure/$name"; else fail "measure/$name" "$bad"; fi
}

# Three disks of radius 1 in a box of side 10, three states (print mode, S = 2).
# step 0: disks 0 and 1 are 1.5 apart (penetration 2 - 1.5 = 0.5); E = (1 + 1 + 0.5) / 2 = 1.25
# step 1: disks 0 and 1 exactly 2 apart (touching is no overlap);  E = (1 + 1 + 0.5) / 2 = 1.25
# step 2: 1.2 apart (penetration 0.8), disk 0 at speed 2; E = (4 + 0 + 0.5) / 2 = 2.25, drift |2.25 - 1.25| / 1.25 = 0.8
# overlaps in 2 of 3 states, 2 pairs / 3 states, mean depth (0.5 + 0.8) / 2 = 0.65, max 0.8;
# kT = mean E / N = (1.25 + 1.25 + 2.25) / 3 / 3 = 0.52777...; counts p = 1 1 0 (1 pair collision),
# w = 2 0 1 (3 wall collisions), over S = 2 time units: 0.5 and 1.5 per time unit.
printf '3\n10\n1\n2\nprint\n' > "$A/three.in"
cat > "$A/three.out" <<'OUT'
0 0 2.00000000 2.00000000 1.00000000 0.00000000
0 1 3.50000000 2.00000000 0.00000000 -1.00000000
0 2 8.00000000 8.00000000 0.50000000 0.50000000
1 0 2.00000000 2.00000000 0.00000000 1.00000000
1 1 4.00000000 2.00000000 -1.00000000 -0.00000000
1 2 8.00000000 8.50000000 0.50000000 0.50000000
2 0 2.00000000 2.00000000 2.00000000 0.00000000 1 2
2 1 3.20000000 2.00000000 0.00000000 0.00000000 1 0
2 2 8.00000000 8.00000000 0.50000000 0.50000000 0 1
OUT
three_want="states=3 n=3 first_step=0 last_step=2 overlap_state_fraction=0.666667 overlap_pairs_per_state=0.666667"
three_want+=" mean_penetration=0.65 max_penetration=0.8 energy_first=1.25 energy_last=2.25 energy_drift=0.8"
three_want+=" kT=0.52777777777777779 pair_collisions=1 wall_collisions=3 pair_collisions_per_time=0.5"
three_want+=" wall_collisions_per_time=1.5"
measure_expect "hand-made print output" "$A/three.in" "$A/three.out" "$three_want"
measure_expect "same from stdin" "$A/three.in" - "$three_want" < "$A/three.out"
# only the deeper of the two overlaps counts with --depth 0.6
measure_expect "--depth 0.6" "$A/three.in" "$A/three.out" \
    "overlap_state_fraction=0.333333 overlap_pairs_per_state=0.333333 mean_penetration=0.8 max_penetration=0.8" \
    --depth 0.6
# the same reals as --dump17 writes them (%.17g: no trailing zeros, exponents)
sed -e 's/\.00000000//g' -e 's/0\.50000000/0.5/g' -e 's/3\.50000000/3.5/' -e 's/8\.50000000/8.5/' \
    -e 's/3\.20000000/3.2000000000000002/' -e 's/^0 2 8 8 0.5 /0 2 8 8 5e-1 /' \
    "$A/three.out" > "$A/three.d17"
measure_expect "hand-made --dump17 output" "$A/three.in" "$A/three.d17" \
    "overlap_pairs_per_state=0.666667 max_penetration=0.79999999999999982 energy_drift=0.8 pair_collisions=1"

# Four disks (grid of 3 x 3 cells, 10/3 wide): the pair 2-3 lies in diagonal neighbour cells, (1,0)
# and (0,1), 0.5 apart in x and y: penetration 2 - sqrt(0.5) = 1.2928932188134525. Perf output
# without counts on step 0 and with them on step 5; no pair or wall collision counted.
printf '4\n10\n1\n5\nperf\n' > "$A/four.in"
cat > "$A/four.out" <<'OUT'
0 0 1.00000000 9.00000000 0.00000000 0.00000000
0 1 9.00000000 9.00000000 0.00000000 0.00000000
0 2 3.50000000 3.00000000 0.00000000 0.00000000
0 3 3.00000000 3.50000000 0.00000000 0.00000000
5 0 1.00000000 9.00000000 0.00000000 0.00000000 0 0
5 1 9.00000000 9.00000000 0.00000000 0.00000000 0 0
5 2 3.50000000 3.00000000 0.00000000 0.00000000 0 0
5 3 3.00000000 3.50000000 0.00000000 0.00000000 0 0
OUT
measure_expect "pair across diagonal cells, perf output" "$A/four.in" "$A/four.out" \
    "states=2 last_step=5 overlap_state_fraction=1 overlap_pairs_per_state=1 max_penetration=1.29289 energy_first=0 energy_drift=0 pair_collisions_per_time=0 wall_collisions_per_time=0"
# without counts there are no collision rates
head -n 4 "$A/four.out" > "$A/four0.out"
measure_expect "no counts, no rates" "$A/four.in" "$A/four0.out" \
    "states=1 pair_collisions=nan pair_collisions_per_time=nan"

# measure_rejects NAME FILTER: a damaged three.out is refused with a message naming the line.
measure_rejects() {
    sh -c "$2" < "$A/three.out" > "$A/bad.out"
    if ./tools/measure "$A/three.in" "$A/bad.out" > /dev/null 2> "$A/err"; then
        fail "measure rejects $1"
    elif grep -q "^measure: $A/bad.out:[0-9]*: " "$A/err"; then
        pass "measure rejects $1"
    else
        fail "measure rejects $1" "message: $(head -c 200 "$A/err")"
    fi
}
measure_rejects "a missing line" "sed 4d"
measure_rejects "a wrong index" "awk 'NR == 2 { \$2 = 2 } 1'"
measure_rejects "a step inside another" "awk 'NR == 5 { \$1 = 2 } 1'"
measure_rejects "a non-number" "awk 'NR == 3 { \$3 = \"x\" } 1'"
measure_rejects "an odd sum of p" "awk 'NR == 9 { \$7 = 1 } 1'"

# ---- --substeps and --pressure in seq and omp ----------------------------------------------------
# S x K sub-steps could overflow a disk's int32 collision counts: refused before any output
printf '1\n1\n0.1\n2097152\nperf\n0 0.5 0.5 1000 0\n' > "$A/long.in"
for prog in seq omp; do
    expect_error "substeps/$prog refuses S x K over 2^31-1" "S x K must be" ./$prog "$A/long.in" --substeps 1024
done
tools/gen 600 --fraction 0.4 --speed 0.8 --steps 30 --mode print --seed 7 > "$A/dense.in"
tools/gen 400 --assignment --L 400 --steps 12 --mode print --seed 8 > "$A/fast.in"
for scene in dense fast; do
    in=$A/$scene.in
    ./seq "$in" --quiet --dump17 > "$A/$scene.ref"
    same_bytes "substeps/$scene --substeps 1 is the SPEC.md step, seq" "$A/$scene.ref" \
        ./seq "$in" --quiet --dump17 --substeps 1
    same_bytes "substeps/$scene --substeps 1 is the SPEC.md step, omp" "$A/$scene.ref" \
        ./omp "$in" --quiet --dump17 --substeps 1 --threads 2
    for k in 2 8; do
        if ! ./seq "$in" --dump17 --substeps "$k" --pressure > "$A/$scene.k$k" 2> "$A/$scene.k$k.err"; then
            fail "substeps/$scene K = $k seq" "$(head -c 300 "$A/$scene.k$k.err")"
            continue
        fi
        want=$(sed -n 's/^seq: pressure: /pressure: /p' "$A/$scene.k$k.err")
        if [ -n "$want" ]; then pass "pressure/$scene K = $k: seq prints the line"; else
            fail "pressure/$scene K = $k: seq prints the line" "$(tail -n 1 "$A/$scene.k$k.err")"; fi
        if cmp -s "$A/$scene.k$k" "$A/$scene.ref"; then fail "substeps/$scene K = $k differs from K = 1"
        else pass "substeps/$scene K = $k differs from K = 1"; fi
        bad=""
        for t in 1 2 3 7; do
            ./omp "$in" --dump17 --substeps "$k" --pressure --threads "$t" > "$A/out" 2> "$A/err" ||
                { bad="$bad $t:exit"; continue; }
            cmp -s "$A/out" "$A/$scene.k$k" || bad="$bad $t:stdout"
            [ "$(sed -n 's/^omp: pressure: /pressure: /p' "$A/err")" = "$want" ] || bad="$bad $t:pressure"
        done
        if [ -z "$bad" ]; then
            pass "substeps/$scene K = $k --pressure: omp = seq at 1, 2, 3, 7 threads (stdout and pressure)"
        else
            fail "substeps/$scene K = $k --pressure: omp = seq" "$bad"
        fi
    done
done

# --exact --pressure: the event loop runs in time order in both, so the impulses add up alike
if ./seq "$A/dense.in" --dump17 --exact --pressure > "$A/dense.exact" 2> "$A/dense.exact.err"; then
    want=$(sed -n 's/^seq: pressure: /pressure: /p' "$A/dense.exact.err")
    bad=""
    [ -n "$want" ] || bad=" seq:no pressure line"
    for t in 1 2 3 7; do
        ./omp "$A/dense.in" --dump17 --exact --pressure --threads "$t" > "$A/out" 2> "$A/err" ||
            { bad="$bad $t:exit($(head -c 200 "$A/err"))"; continue; }
        cmp -s "$A/out" "$A/dense.exact" || bad="$bad $t:stdout"
        [ "$(sed -n 's/^omp: pressure: /pressure: /p' "$A/err")" = "$want" ] || bad="$bad $t:pressure"
    done
    if [ -z "$bad" ]; then pass "pressure/dense --exact: omp = seq at 1, 2, 3, 7 threads (stdout and pressure)"
    else fail "pressure/dense --exact: omp = seq" "$bad"; fi
else
    fail "pressure/dense --exact: seq" "$(head -c 300 "$A/dense.exact.err")"
fi

# One disk from x = 5 at speed 1 in a box of side 10, r = 1: it meets the wall x = 9 at the end of
# step 4 (an event at t = 1), comes back to x = 5 at step 8. One reflection, impulse 2 |vx| = 2;
# P = 2 / (4 walls x 10 x 8 time units) = 0.00625, whatever K, and with --exact.
printf '1\n10\n1\n8\nperf\n0 5 5 1 0\n' > "$A/bounce.in"
for prog in seq omp; do
    for k in 1 4 exact; do
        opts=(--substeps "$k")
        [ "$k" != exact ] || opts=(--exact)
        line=$(./$prog "$A/bounce.in" --pressure "${opts[@]}" 2>&1 >/dev/null | grep ': pressure: ' || true)
        if [ "$line" = "$prog: pressure: wall impulse 2 over 8 time units on 4 walls of length 10: P = 0.0062500000000000003" ]; then
            pass "pressure/bounce $prog ${opts[*]}: by hand"
        else
            fail "pressure/bounce $prog ${opts[*]}: by hand" "got '$line'"
        fi
    done
done

# ---- ./bench.sh accuracy --quick --------------------------------------------------------------------
acc_csv=$A/accuracy-quick.csv
acc_rungs="k1 k2 k4 k8 exact f32"
if RUNGS=$acc_rungs ./bench.sh accuracy --quick -o "$acc_csv" > "$A/accuracy.log" 2>&1; then
    pass "accuracy.sh --quick runs"
else
    fail "accuracy.sh --quick runs" "$(tail -n 2 "$A/accuracy.log")"
fi
acc_problem=$(awk -F, -v rungs="$acc_rungs" '
    /^#/ { if (header) { print "comment after the header"; exit }; prov[substr($0, 3)] = 1; next }
    !header {
        header = $0; nf = NF
        for (k = 1; k <= NF; k++) col[$k] = k
        split("rung eta n z z_henderson deviation_pct min_ns_per_particle_step energy_drift overlap_state_fraction max_penetration_over_r pair_collisions_per_time", need, " ")
        for (k in need) if (!(need[k] in col)) { print "no column " need[k]; exit }
        next
    }
    NF != nf { print "line " NR " has " NF " fields, not " nf; exit }
    {
        for (k = 3; k <= NF; k++) if ($k !~ /^-?[0-9.]+(e[+-]?[0-9]+)?$/) { print "line " NR " field " k " not a number: " $k; exit }
        if (!($col["z"] > 0.5 && $col["z"] < 10 && $col["min_ns_per_particle_step"] > 0 && $col["overlap_state_fraction"] <= 1)) {
            print "line " NR ": implausible: " $0; exit
        }
        seen[$col["rung"] "/" $col["eta"]] = 1; rows++
    }
    END {
        if (!header) { print "no header"; exit }
        split("git: date: cpu: cc: CFLAGS: OMP_PROC_BIND", p, " ")
        for (k in p) { found = 0; for (q in prov) if (index(q, p[k]) == 1) found = 1; if (!found) { print "no provenance line " p[k]; exit } }
        n = split(rungs, r, " ")
        for (k = 1; k <= n; k++) if (!((r[k] "/0.2") in seen) || !((r[k] "/0.4") in seen)) { print "no row of rung " r[k]; exit }
        if (rows != 2 * n) print rows " rows, expected " 2 * n
    }' "$acc_csv" 2>&1 | head -n 1)
[ -s "$acc_csv" ] || acc_problem="no $acc_csv"
if [ -z "$acc_problem" ]; then pass "accuracy.sh --quick CSV well formed, every rung"; else
    fail "accuracy.sh --quick CSV well formed, every rung" "$acc_problem"; fi
