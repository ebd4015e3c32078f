#!/usr/bin/env bash
# ./bench.sh dense: the hard-disk equation of state in the periodic box (--periodic), against the
# published references of bench/eos_reference.md.
#   fluid  N_FLUID disks at FLUID_FRACTIONS: --exact, its collision-virial Z (--pressure) against
#          Kolafa and Rottner's fluid equation of state (to eta 0.69)
#   loop   N_LOOP disks at LOOP_FRACTIONS, across melting: --exact against the event-driven MD pressure
#          of Engel et al. at N = 256^2 (the Mayer-Wood loop)
#   rungs  from each fluid point's equilibrated state: the SPEC.md step and --substeps K, their Z against
#          --exact's, their overlaps (tools/measure) and cost
# Each point: a scene (random placement up to eta 0.5, else a triangular crystal, tools/gen --lattice),
# EQ_COLL collisions a disk of --exact to equilibrate (not measured), then MEAS_COLL a disk measured.
# One CSV row a point (provenance in its # lines), a table on stdout, the figure beside the CSV.
# JOBS points run at once, each on THREADS threads (a few threads a run use cores best).
# --plot: no runs; the table and figure of OUTPUT as it stands (CSVs of several machines joined).
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/../.."
. bench/cmd/lib.sh

# ---- knobs (environment variables of the same name override them) ----------------------------------
PARTS=${PARTS:-"fluid rungs"}
N_FLUID=${N_FLUID:-10000}   # disks of the fluid points (the nearest crystal count of tools/gen --lattice)
N_LOOP=${N_LOOP:-65536}     # disks of the loop's points (likewise)
FLUID_FRACTIONS=${FLUID_FRACTIONS:-"0.1 0.2 0.3 0.4 0.5 0.55 0.6 0.65"}
LOOP_FRACTIONS=${LOOP_FRACTIONS:-"0.698 0.700 0.704 0.708 0.712 0.716 0.720"}
RUNGS=${RUNGS:-"k1 k2 k4 k8"} # kK: the SPEC.md step with --substeps K (k1: none)
SPEED=${SPEED:-1}           # tools/gen --speed: speeds uniform in [0, SPEED r] a step; kT = SPEED^2 r^2 / 6
EQ_COLL=${EQ_COLL:-200}     # collisions a disk of --exact before measuring
MEAS_COLL=${MEAS_COLL:-400} # collisions a disk measured
RUNG_STEPS=${RUNG_STEPS:-200} # steps of each rung's measured run; its print run for overlaps: a tenth
THREADS=${THREADS:-$(nproc 2>/dev/null || echo 1)} # threads of each run
JOBS=${JOBS:-1}             # points run at once (each on THREADS threads): JOBS x THREADS <= the cores
SEED=${SEED:-1}
OUTPUT=${OUTPUT:-bench/dense.csv}
TMP_DIR=${TMP_DIR:-bench/tmp/dense}
if [ "${1:-}" = --help ] || [ "${1:-}" = -h ]; then sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'; exit 0; fi
PLOT_ONLY=0
[ "${1:-}" = --plot ] && PLOT_ONLY=1
if [ "${1:-}" = --quick ]; then # a check of the script: seconds on 2 cores
    N_FLUID=500 N_LOOP=800 FLUID_FRACTIONS="0.3 0.65" LOOP_FRACTIONS="0.71" EQ_COLL=5 MEAS_COLL=10 RUNG_STEPS=10
    PARTS="fluid loop rungs" OUTPUT=${OUTPUT_QUICK:-bench/tmp/dense-quick.csv}
fi
die() { echo "dense.sh: $*" >&2; exit 1; }
[ -x tools/gen ] && [ -x tools/measure ] && [ -x omp ] || die "build first (make)"
mkdir -p "$TMP_DIR" "$(dirname "$OUTPUT")"

# ---- the references (bench/eos_reference.md) ---------------------------------------------------------
# Kolafa and Rottner (2006), Eq. (7), the fit to rho* = 0.90: Z = sum A_i x^i, x = eta / (1 - eta)
KR='function kr(eta,   x, a, z, i, p) {
        split("1 2 1.12801775 0.00181895291 -0.0526134737 0.0504960168 -0.0325537792 0.0134578632 " \
              "0.00140888182 -0.00834273601 0.00694127367 -0.00262254723 0.000355746352", a, " ")
        x = eta / (1 - eta); z = 0; p = 1
        for (i = 0; i <= 12; i++) { z += a[i + 1] * p; p *= x }
        return z - 5.24672938e-9 * x ^ 22 + 5.88054639e-23 * x ^ 57
    }'
# Engel et al. (2013), event-driven MD, N = 256^2: beta P d^2 at eta (bench/eos_reference.md, section 3),
# interpolated linearly between the tabulated fractions
ENGEL="0.698 9.17059 0.700 9.18896 0.702 9.19144 0.704 9.18903 0.706 9.18585 0.708 9.18226 0.710 9.17914
0.712 9.17715 0.714 9.17563 0.716 9.17823 0.718 9.18468 0.720 9.22350"
ENGEL_AWK='function engel(eta,   t, m, k) {
        m = split(ENGEL, t, " ")
        for (k = 1; k + 3 <= m; k += 2)
            if (eta >= t[k] - 1e-9 && eta <= t[k + 2] + 1e-9)
                return t[k + 1] + (t[k + 3] - t[k + 1]) * (eta - t[k]) / (t[k + 2] - t[k])
        return -1
    }'

# lattice_n N: the count nearest N of a triangular crystal tools/gen --lattice makes (nx ny, ny even,
# ny / nx within 0.5% of 2 / sqrt(3))
lattice_n() {
    awk -v want="$1" 'BEGIN { best = 0
        for (nx = 2; nx < 4 * sqrt(want) + 10; nx++)
            for (ny = 2; ny < 4 * sqrt(want) + 10; ny += 2) {
                ratio = ny / nx / (2 / sqrt(3)); if (ratio < 0.995 || ratio > 1.005) continue
                if (!best || (nx * ny - want) ^ 2 < (best - want) ^ 2) best = nx * ny
            }
        print best }'
}

# collision_rate ETA Z: collisions a disk a time unit (Enskog: 2 d n g sqrt(pi kT), g = (Z - 1) / (2 eta)),
# with kT = SPEED^2 / 6 (r = 1)
collision_rate() {
    awk -v eta="$1" -v z="$2" -v s="$SPEED" 'BEGIN {
        g = (z - 1) / (2 * eta); n = eta / 3.141592653589793
        printf "%.6g\n", 2 * 2 * n * g * sqrt(3.141592653589793 * s * s / 6) }'
}

# steps_for COLL ETA Z: the steps that give about COLL collisions a disk (at least 10)
steps_for() {
    awk -v c="$1" -v rate="$(collision_rate "$2" "$3")" 'BEGIN { s = int(c / rate + 0.5); print s < 10 ? 10 : s }'
}

# with_header INPUT STEPS MODE: the input with its steps and mode records replaced
with_header() { { head -n 3 "$1"; echo "$2"; echo "$3"; tail -n +6 "$1"; }; }
# state_input OUTPUT BASE N: an input (BASE's N, L, r) whose disks are OUTPUT's final state (--dump17)
state_input() { head -n 3 "$2"; printf '1\nperf\n'; tail -n "$3" "$1" | awk '{ print $2, $3, $4, $5, $6 }'; }
# virial ERR: "Z error" from a --periodic --pressure run's stderr
virial() { sed -n 's/.*Z = P L^2 \/ (N kT) = \([0-9.e+-]*\) +- \([0-9.e+-]*\) .*/\1 \2/p' "$1" | tail -n 1; }
# run PROGRAM IN OUT ERR ARGS...
run() {
    local prog=$1 in=$2 out=$3 err=$4
    shift 4
    "$prog" "$in" --periodic --threads "$THREADS" "$@" > "$out" 2> "$err" || die "$prog $in $*: $(tail -n 2 "$err")"
}

COLUMNS="part,rung,eta,n,L,steps,collisions_per_disk,z,z_stderr,z_reference,deviation_pct,deviation_stderr_pct"
COLUMNS+=",beta_p_d2,reference,overlap_state_fraction,max_penetration_over_r,energy_drift,ns_per_particle_step"

# point PART ETA N: one point's equilibration and --exact measurement, and with PART rungs its rungs
point() {
    local part=$1 eta=$2 n=$3 tag=$TMP_DIR/$1-$2 zref ref s_eq s_meas line z zerr secs L
    if awk -v e="$eta" 'BEGIN { exit !(e <= 0.5) }'; then
        tools/gen "$n" --periodic --fraction "$eta" --speed "$SPEED" --steps 1 --seed "$SEED" > "$tag.gen"
    else
        tools/gen "$n" --lattice --fraction "$eta" --speed "$SPEED" --steps 1 --seed "$SEED" > "$tag.gen"
    fi
    if [ "$part" = loop ]; then
        zref=$(awk -v eta="$eta" -v ENGEL="$ENGEL" "$ENGEL_AWK"' BEGIN { p = engel(eta); print p < 0 ? -1 : p * 3.141592653589793 / (4 * eta) }')
        ref="Engel et al. 2013 (EDMD at N = 256^2)"
    else
        zref=$(awk -v eta="$eta" "$KR"' BEGIN { printf "%.8g\n", eta <= 0.6912 ? kr(eta) : -1 }')
        ref="Kolafa and Rottner 2006 (Eq. 7)"
    fi
    local zest=$zref
    awk -v z="$zest" 'BEGIN { exit !(z <= 0) }' && zest=$(awk -v eta="$eta" "$KR"' BEGIN { print kr(eta > 0.69 ? 0.69 : eta) }')
    s_eq=$(steps_for "$EQ_COLL" "$eta" "$zest")
    s_meas=$(steps_for "$MEAS_COLL" "$eta" "$zest")
    with_header "$tag.gen" "$s_eq" perf > "$tag.in"
    run ./omp "$tag.in" "$tag.out" "$tag.err" --exact --dump17 --quiet
    state_input "$tag.out" "$tag.gen" "$n" > "$tag.eq"
    with_header "$tag.eq" "$s_meas" perf > "$tag.in"
    run ./omp "$tag.in" "$tag.out" "$tag.err" --exact --dump17 --pressure --stats
    read -r z zerr <<< "$(virial "$tag.err")"
    [ -n "${z:-}" ] || die "no virial line: $(tail -n 2 "$tag.err")"
    secs=$(loop_seconds "$tag.err")
    L=$(sed -n 2p "$tag.gen")
    local events m
    events=$(sed -n 's/.*, \([0-9]*\) events$/\1/p' "$tag.err" | tail -n 1)
    m=$(tools/measure --periodic "$tag.in" "$tag.out")
    fields "$part" exact "$eta" "$n" "$L" "$s_meas" "$(awk -v e="${events:-0}" -v n="$n" 'BEGIN { printf "%.4g", 2 * e / n }')" \
        "$z" "$zerr" "$zref" "$ref" "$(value_of overlap_state_fraction "$m")" "$(value_of max_penetration "$m")" \
        "$(value_of energy_drift "$m")" "$(awk -v s="$secs" -v n="$n" -v t="$s_meas" 'BEGIN { printf "%.4g", s * 1e9 / (n * t) }')"
    echo "dense.sh: $part eta $eta N $n: Z = $z +- $zerr (reference $zref), $s_meas steps" >&2
    [ "$part" = fluid ] && [[ " $PARTS " == *" rungs "* ]] || return 0
    local rung k opts
    for rung in $RUNGS; do
        k=${rung#k}
        opts=()
        [ "$k" = 1 ] || opts=(--substeps "$k")
        with_header "$tag.eq" "$RUNG_STEPS" perf > "$tag.rin"
        run ./omp "$tag.rin" "$tag.rout" "$tag.rerr" "${opts[@]}" --dump17 --pressure
        read -r z zerr <<< "$(virial "$tag.rerr")"
        secs=$(loop_seconds "$tag.rerr")
        with_header "$tag.eq" $((RUNG_STEPS / 10 > 2 ? RUNG_STEPS / 10 : 2)) print > "$tag.pin"
        run ./omp "$tag.pin" "$tag.pout" "$tag.perr" "${opts[@]}" --quiet
        m=$(tools/measure --periodic --depth 1e-6 "$tag.pin" "$tag.pout")
        events=$(awk '{ p += $7 } END { print p }' <(tail -n "$n" "$tag.rout"))
        fields rungs "$rung" "$eta" "$n" "$L" "$RUNG_STEPS" "$(awk -v p="$events" -v n="$n" 'BEGIN { printf "%.4g", p / n }')" \
            "$z" "$zerr" "$zref" "$ref" "$(value_of overlap_state_fraction "$m")" "$(value_of max_penetration "$m")" \
            nan "$(awk -v s="$secs" -v n="$n" -v t="$RUNG_STEPS" 'BEGIN { printf "%.4g", s * 1e9 / (n * t) }')"
        echo "dense.sh: rung $rung eta $eta: Z = $z +- $zerr" >&2
    done
}
value_of() { echo "$2" | tr ' ' '\n' | sed -n "s/^$1=//p" | head -n 1; }
# fields VALUE...: one point's raw line, its values apart by "|" (the reference's name holds spaces)
fields() { local IFS='|'; echo "$*" >> "$OUTPUT.raw"; }

if [ "$PLOT_ONLY" = 0 ]; then
    : > "$OUTPUT.raw"
    START=$EPOCHREALTIME
    LOAD_START=$(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo unknown)
    nf=$(lattice_n "$N_FLUID") nl=$(lattice_n "$N_LOOP")
    # at most JOBS points at once; a point that fails stops the script once the others end
    todo=()
    if [[ " $PARTS " == *" fluid "* ]] || [[ " $PARTS " == *" rungs "* ]]; then
        for eta in $FLUID_FRACTIONS; do todo+=("fluid $eta $nf"); done
    fi
    if [[ " $PARTS " == *" loop "* ]]; then
        for eta in $LOOP_FRACTIONS; do todo+=("loop $eta $nl"); done
    fi
    running=0 failed=0
    for job in "${todo[@]}"; do
        if [ "$running" -ge "$JOBS" ]; then
            wait -n || failed=1
            running=$((running - 1))
        fi
        # shellcheck disable=SC2086
        point $job &
        running=$((running + 1))
    done
    while [ "$running" -gt 0 ]; do
        wait -n || failed=1
        running=$((running - 1))
    done
    [ "$failed" = 0 ] || die "a point failed (its message above)"
    # the rows in the order of the points (they end in any order): fluid, rungs, loop, each by eta
    sort -t'|' -s -k1,1 -k3,3g "$OUTPUT.raw" | awk -F'|' '$1 == "fluid" { print; next } { rest[++k] = $0 }
        END { for (i = 1; i <= k; i++) if (rest[i] ~ /^rungs/) print rest[i]; for (i = 1; i <= k; i++) if (rest[i] ~ /^loop/) print rest[i] }' \
        > "$OUTPUT.sorted"
    mv "$OUTPUT.sorted" "$OUTPUT.raw"

    # ---- the CSV, the table, the figure -----------------------------------------------------------------
    {
        echo "# ./bench.sh dense results (REPORT.md 5; references: bench/eos_reference.md)"
        echo "# PARTS=\"$PARTS\" N_FLUID=$N_FLUID ($nf disks) N_LOOP=$N_LOOP ($nl) SPEED=$SPEED EQ_COLL=$EQ_COLL" \
            "MEAS_COLL=$MEAS_COLL RUNG_STEPS=$RUNG_STEPS THREADS=$THREADS SEED=$SEED"
        machine_provenance "$LOAD_START" "$(nproc 2>/dev/null)"
        echo "# Z: the collision virial of --periodic --pressure over the measured run, its error the standard" \
            "error of 10 block means; rungs start from the fluid point's equilibrated --exact state"
        echo "$COLUMNS"
        awk -F'|' '{ zr = $10 + 0; known = zr > 0
            d = known ? sprintf("%.4f", 100 * ($8 - zr) / zr) : "nan"
            de = known ? sprintf("%.4f", 100 * $9 / zr) : "nan"
            printf "%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%.6g,%s,%s,%s,%s,%s\n", $1, $2, $3, $4, $5, $6, $7, $8, $9,
                (known ? zr : "nan"), d, de, 4 * $3 * $8 / 3.141592653589793, (known ? $11 : "none"),
                ($12 == "" ? "nan" : $12), ($13 == "" ? "nan" : $13), ($14 == "" ? "nan" : $14), $15 }' "$OUTPUT.raw"
    } > "$OUTPUT.part"
    mv "$OUTPUT.part" "$OUTPUT"
    rm -f "$OUTPUT.raw"
    echo "dense.sh: $OUTPUT written in $(awk -v a="$START" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.0f", b - a }') s" >&2
fi
grep -v '^#' "$OUTPUT" | awk -F, 'NR == 1 { print "| part | rung | eta | N | collisions a disk | Z | reference | deviation % | overlaps (fraction of states) | ns per particle-step |"
    print "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"; next }
    { printf "| %s | %s | %s | %s | %s | %s +- %s | %s | %s +- %s | %s | %s |\n", $1, $2, $3, $4, $7, $8, $9, $10, $11, $12, $15, $18 }'
if command -v gnuplot > /dev/null 2>&1; then
    png=${OUTPUT%.csv}.png work=$(mktemp -d)
    grep -v '^#' "$OUTPUT" | awk -F, -v dir="$work" 'NR > 1 && $2 == "exact" { print $3, $8, $9 > (dir "/" $1) }
        NR > 1 && $2 != "exact" { print $3, $8, $9 > (dir "/" $2) }'
    awk "$KR"' BEGIN { for (e = 0.02; e <= 0.6905; e += 0.005) print e, kr(e) }' > "$work/kr"
    awk -v ENGEL="$ENGEL" 'BEGIN { m = split(ENGEL, t, " "); for (k = 1; k < m; k += 2) print t[k], t[k + 1] * 3.141592653589793 / (4 * t[k]) }' > "$work/engel"
    {
        echo "set terminal pngcairo size 1300,560 font ',10'; set output '$png'"
        echo "set multiplot layout 1,2 title 'Hard disks in the periodic box: Z = PA / (N kT), omp --exact and the SPEC.md step'"
        echo "set xlabel 'area fraction'; set ylabel 'Z'; set key top left; set grid"
        p="'$work/kr' with lines lw 2 title 'Kolafa and Rottner 2006 (fluid)', '$work/engel' with linespoints pt 6 title 'Engel et al. 2013, N = 256^2'"
        for f in fluid loop; do [ -s "$work/$f" ] && p="$p, '$work/$f' using 1:2:3 with yerrorbars pt 7 title '--exact ($f)'"; done
        for r in $RUNGS; do [ -s "$work/$r" ] && p="$p, '$work/$r' using 1:2 with points pt 4 title 'step, --substeps ${r#k}'"; done
        echo "plot $p"
        echo "set xrange [0.695:0.724]; set title 'melting: the Mayer-Wood loop'; set key top right"
        p="'$work/engel' with linespoints pt 6 title 'Engel et al. 2013, N = 256^2'"
        [ -s "$work/loop" ] && p="$p, '$work/loop' using 1:2:3 with yerrorbars pt 7 title '--exact'"
        echo "plot $p"
        echo "unset multiplot"
    } > "$work/fig.gp"
    gnuplot "$work/fig.gp" && echo "dense.sh: figure $png" >&2
    rm -rf "$work"
fi
