#!/usr/bin/env bash
# ./bench.sh accuracy: what accuracy costs in time. Runs the accuracy ladder (rungs: the SPEC.md step,
# --substeps 2, 4, 8, --exact, the float build) on closed boxes of hard disks at several area fractions,
# measures the pressure through the walls (--pressure) and compares the compressibility factor
# Z = P A / (N kT) with Henderson's hard-disk equation of state; tools/measure adds overlaps, energy
# drift and collision rates. Writes one CSV row per (rung, scene) with a provenance header, a markdown
# table on stdout and, where gnuplot is installed, the figure "error against time" beside the CSV.
# REPORT.md ("What accuracy costs in time") discusses the results.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/../.."

# ---- knobs (environment variables of the same name override them; options override both) ----------
N=${N:-10000}                           # disks per scene
FRACTIONS=${FRACTIONS:-"0.1 0.2 0.3 0.4"} # area fractions eta = N pi r^2 / L^2 of the scenes
# Speeds uniform in [0, SPEED * r] per step: a disk moves a fraction of r per step, so the SPEC.md step
# (one collision per disk per step) is a fair, not a hopeless, approximation, the broad phase stays
# cheap, and --substeps K has something to converge to. Hard disks have no energy scale: Z does not
# depend on the speeds, which only set how many steps a collision takes.
SPEED=${SPEED:-0.5}
RUNGS=${RUNGS:-"k1 k2 k4 k8 exact f32"} # kK: omp --substeps K (k1: no option); exact: omp --exact;
                                        # f32: omp_f32 (float build, SPEC.md step)
EQ_STEPS=${EQ_STEPS:-300}       # equilibration of each rung from the generated scene, not measured
BLOCKS=${BLOCKS:-8}             # measured runs, each continuing the last; their spread gives Z's error
BLOCK_STEPS=${BLOCK_STEPS:-500} # steps (time units) of one measured run
PRINT_STEPS=${PRINT_STEPS:-100} # print-mode run (%.8f) from the equilibrated state, for the overlaps
TIME_ROUNDS=${TIME_ROUNDS:-8}   # timing rounds after the measured runs: every scene and rung in turn
TIME_STEPS=${TIME_STEPS:-100}   # steps of one timing run
DEPTH=${DEPTH:-1e-6}            # overlaps shallower than DEPTH * r are not counted (%.8f resolves 1e-8)
THREADS=${THREADS:-$(nproc 2>/dev/null || echo 1)} # omp threads: all cores
SEED=${SEED:-1}
RUN_TIMEOUT=${RUN_TIMEOUT:-600} # seconds before one run counts as hung
OUTPUT=${OUTPUT:-bench/accuracy.csv}
TMP_DIR=${TMP_DIR:-bench/tmp/accuracy}
export OMP_PROC_BIND=${OMP_PROC_BIND:-close}
export OMP_PLACES=${OMP_PLACES:-cores}

usage() {
    cat <<EOF
usage: ./bench.sh accuracy [options]
For each area fraction eta and each rung: tools/gen N --fraction eta --speed $SPEED, EQ_STEPS steps of
equilibration, BLOCKS measured runs of BLOCK_STEPS steps with --pressure (each continuing the last
one's final state, --dump17 so nothing is lost), and a print-mode run of PRINT_STEPS steps for
tools/measure. Writes OUTPUT (default $OUTPUT), its figure OUTPUT minus .csv plus .png (needs gnuplot),
and the table on stdout.

options (lists are space- or comma-separated):
  --quick            CI-sized study, under 30 s on 2 cores: N = 1000, eta 0.2 and 0.4, short runs,
                     output bench/tmp/accuracy-quick.csv unless -o is given
  --rungs LIST       from: k1 k2 k4 ... k1024 exact f32 (default: $RUNGS)
  --fractions LIST   area fractions (default: $FRACTIONS)
  --n N              disks per scene (default $N)
  --blocks B         measured runs per point (default $BLOCKS)
  --block-steps S    steps per measured run (default $BLOCK_STEPS)
  -o, --output FILE  CSV (default $OUTPUT)
  --plot FILE        only draw the figure of an existing CSV
  --help             this text
Knobs at the top of this file can also be set as environment variables (EQ_STEPS, PRINT_STEPS, SPEED,
DEPTH, THREADS, SEED, ...).
EOF
}

die() { echo "accuracy.sh: $*" >&2; exit 1; }
. bench/cmd/lib.sh

# ---- the figure -------------------------------------------------------------------------------------
# plot CSV: the figure, two panels with one point per rung and scene (a colour per scene; a line joins
# the sub-step rungs K = 1, 2, 4, 8 of a scene in order of K), against ns per particle-step (the best of
# a point's timed runs: the machine is shared, and the least disturbed run is closest to the cost):
# left, |Z - Z_Henderson| / Z_Henderson, the error the study is about; right, |Z - Z_exact| / Z_exact
# against the --exact rung of the same scene, the error of the dynamics alone (both runs share the
# box's finite-size effect, and the statistical error of each Z, about 0.1-0.7%, is the floor; values
# below 0.01% are drawn at 0.01%).
plot() {
    local csv=$1 png=${1%.csv}.png work where eta f k=0 terminal=pngcairo panel title plots
    command -v gnuplot >/dev/null 2>&1 || { echo "accuracy.sh: no figure (gnuplot not found)" >&2; return 0; }
    gnuplot -e "set terminal pngcairo" >/dev/null 2>&1 || terminal=png
    work=$(mktemp -d)
    grep -v '^#' "$csv" | awk -F, -v dir="$work" '
        function out(name, d) { if (d < 0) d = -d; if (d < 0.01) d = 0.01; print x[r], d, rung[r] > (dir "/" name) }
        NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k; next }
        { r++; eta[r] = $col["eta"]; rung[r] = $col["rung"]; z[r] = $col["z"]; dev[r] = $col["deviation_pct"]
          x[r] = $col["min_ns_per_particle_step"]; if (rung[r] == "exact") zx[eta[r]] = z[r] }
        END {
            for (r = 1; r <= NR - 1; r++) {
                kind = rung[r] ~ /^k[0-9]+$/ ? "substeps" : "other"
                out("henderson." eta[r] "." kind, dev[r])
                if ((eta[r] in zx) && rung[r] != "exact") out("exact." eta[r] "." kind, 100 * (z[r] - zx[eta[r]]) / zx[eta[r]])
            }
        }'
    where=$(sed -n 's/^# cpu: \(.*\); cores: \(.*\)/\1, \2 cores/p' "$csv" | head -n 1)
    {
        echo "set terminal $terminal size 1400,600 font ',10'"
        echo "set output '$png'"
        echo "set logscale xy; set grid; set key top right"
        echo "set xlabel 'ns per particle-step (one time unit), best of the timed runs'"
        echo "set multiplot layout 1,2 title \"What accuracy costs: omp on $where; lines: --substeps K = 1, 2, 4, 8 in order of K; squares: --exact and the float build\""
        for panel in henderson exact; do
            if [ "$panel" = henderson ]; then
                echo "set ylabel '|Z - Z_{Henderson}| / Z_{Henderson} (%)'; set title 'Error against the equation of state'"
                echo "set yrange [*:5<*]; set arrow 1 from graph 0, first 2 to graph 1, first 2 nohead dashtype 2 linecolor 'gray'"
                echo "set label 1 '2%' at graph 0.01, first 2.15 textcolor 'gray'"
            else
                echo "set ylabel '|Z - Z_{exact}| / Z_{exact} (%)'; set title 'Error of the dynamics: against --exact in the same box'"
            fi
            plots="" k=0
            for eta in $(ls "$work" | sed -n "s/^$panel\.\(.*\)\.[a-z]*$/\1/p" | sort -g -u); do
                k=$((k + 1))
                for f in "$work/$panel.$eta.substeps" "$work/$panel.$eta.other"; do
                    [ -e "$f" ] || continue
                    case $f in
                        *.substeps) plots="$plots${plots:+, }'$f' using 1:2 with linespoints linetype $k pointtype 7 title 'eta = $eta'" ;;
                        *) plots="$plots${plots:+, }'$f' using 1:2 with points linetype $k pointtype 5 pointsize 1.3 notitle" ;;
                    esac
                    plots="$plots, '$f' using 1:2:3 with labels offset 0.7,0.6 left font ',8' textcolor lt $k notitle"
                done
            done
            [ -n "$plots" ] && echo "plot $plots" || echo "set multiplot next"
            echo "unset arrow 1; unset label 1; set autoscale y"
        done
        echo "unset multiplot"
    } > "$work/figure.gp"
    gnuplot "$work/figure.gp" || { rm -rf "$work"; die "gnuplot failed on $csv"; }
    rm -rf "$work"
    echo "accuracy.sh: figure $png" >&2
}

# ---- options --------------------------------------------------------------------------------------
QUICK=0 OUTPUT_GIVEN=0
COMMAND_LINE="./bench.sh accuracy $*"
while [ $# -gt 0 ]; do
    case $1 in
        --help | -h) usage; exit 0 ;;
        --quick) QUICK=1 ;;
        --rungs) RUNGS=$(words "${2?--rungs needs a list}"); shift ;;
        --fractions) FRACTIONS=$(words "${2?--fractions needs a list}"); shift ;;
        --n) N=$(integer "${2?--n needs a number}"); shift ;;
        --blocks) BLOCKS=$(integer "${2?--blocks needs a number}"); shift ;;
        --block-steps) BLOCK_STEPS=$(integer "${2?--block-steps needs a number}"); shift ;;
        -o | --output) OUTPUT=${2?-o needs a file}; OUTPUT_GIVEN=1; shift ;;
        --plot) plot "${2?--plot needs a CSV}"; exit 0 ;;
        *) usage >&2; die "unknown option '$1'" ;;
    esac
    shift
done
if [ "$QUICK" = 1 ]; then
    N=1000 FRACTIONS="0.2 0.4" EQ_STEPS=50 BLOCKS=2 BLOCK_STEPS=50 PRINT_STEPS=20 TIME_ROUNDS=1 TIME_STEPS=20
    [ "$OUTPUT_GIVEN" = 1 ] || OUTPUT=bench/tmp/accuracy-quick.csv
fi
[ "$BLOCKS" -ge 2 ] || die "--blocks must be at least 2 (their spread is the error of Z)"
[ -x tools/gen ] && [ -x tools/measure ] || die "tools/gen or tools/measure not built (run make)"
make -q all >/dev/null 2>&1 || echo "accuracy.sh: warning: binaries older than their sources (run make)" >&2
mkdir -p "$TMP_DIR" "$(dirname "$OUTPUT")"

# ---- rungs ----------------------------------------------------------------------------------------
# rung_command NAME: sets PROG and OPTS (the program and its accuracy options) for a rung.
rung_command() {
    case $1 in
        k1) PROG=./omp OPTS=() ;;
        k[0-9]*) PROG=./omp OPTS=(--substeps "${1#k}") ;;
        exact) PROG=./omp OPTS=(--exact) ;;
        f32) PROG=./omp_f32 OPTS=() ;;
        *) die "unknown rung '$1'" ;;
    esac
}
# every rung must run before the study starts, not fail after minutes
printf '2\n10\n1\n1\nperf\n0 2 2 1 0\n1 8 2 -1 0\n' > "$TMP_DIR/probe.in"
for rung in $RUNGS; do
    rung_command "$rung"
    [ -x "$PROG" ] || die "rung $rung: $PROG not built (run make)"
    "$PROG" "$TMP_DIR/probe.in" "${OPTS[@]}" --pressure --quiet --threads 1 > /dev/null 2> "$TMP_DIR/probe.err" ||
        die "rung $rung: $PROG ${OPTS[*]} --pressure does not run: $(head -n 1 "$TMP_DIR/probe.err")"
done

# ---- running --------------------------------------------------------------------------------------
# with_header INPUT STEPS MODE: the input with its steps and mode records replaced (files written by
# tools/gen and by state_input have the five header records on lines 1-5).
with_header() {
    { head -n 3 "$1"; echo "$2"; echo "$3"; tail -n +6 "$1"; }
}
# state_input OUTPUT BASE: an input (BASE's N, L, r; 1 step, perf) whose disks are OUTPUT's final state,
# exactly when OUTPUT was written with --dump17.
state_input() {
    head -n 3 "$2"
    printf '1\nperf\n'
    tail -n "$N" "$1" | awk '{ print $2, $3, $4, $5, $6 }'
}
# run_prog IN OUT ERR ARGS...: the rung's program on IN; fails the study with its message.
run_prog() {
    local in=$1 out=$2 err=$3
    shift 3
    if ! timeout "$RUN_TIMEOUT" "$PROG" "$in" "${OPTS[@]}" --threads "$THREADS" "$@" > "$out" 2> "$err"; then
        die "$PROG $in ${OPTS[*]} $* failed: $(tail -n 2 "$err")"
    fi
}
# value KEY LINE: a value of tools/measure's key=value line.
value() { echo "$2" | tr ' ' '\n' | sed -n "s/^$1=//p"; }

# ns_per_step SECONDS STEPS: a step loop's time per particle-step of N disks, in ns
ns_per_step() { awk -v x="$1" -v n="$N" -v s="$2" 'BEGIN { printf "%.6g\n", x * 1e9 / (n * s) }'; }

# ---- provenance -----------------------------------------------------------------------------------
provenance() {
    echo "# ./bench.sh accuracy results (REPORT.md, What accuracy costs in time, explains the columns)"
    echo "# command: $COMMAND_LINE"
    machine_provenance "$LOAD_START" "$(nproc 2>/dev/null)"
    echo "# OMP_PROC_BIND=$OMP_PROC_BIND OMP_PLACES=$OMP_PLACES; omp threads: $THREADS"
    echo "# scenes: tools/gen $N --fraction ETA --speed $SPEED --seed $SEED for ETA in $FRACTIONS; rungs: $RUNGS"
    echo "# per point: $EQ_STEPS steps of equilibration, $BLOCKS x $BLOCK_STEPS measured steps" \
        "(--pressure --dump17, perf), $PRINT_STEPS print-mode steps for overlaps deeper than $DEPTH r," \
        "$TIME_ROUNDS timing rounds of $TIME_STEPS steps (every scene and rung in turn)"
    echo "# Z = P L^2 / (N kT), kT = <v^2>/2 per measured run; Z_henderson = (1 + eta^2/8) / (1 - eta)^2;" \
        "enskog rate = 2 (2r) n g sqrt(pi kT), g = (Z_henderson - 1) / (2 eta)"
}

COLUMNS="rung,program,eta,n,L,r,threads,steps,timed_runs,min_ns_per_particle_step,median_ns_per_particle_step"
COLUMNS+=",time_over_k1,kT,P"
COLUMNS+=",z,z_stderr,z_henderson,deviation_pct,deviation_stderr_pct,pair_collisions_per_time"
COLUMNS+=",wall_collisions_per_time,pair_collisions_per_disk_time,enskog_pair_collisions_per_disk_time"
COLUMNS+=",energy_drift,overlap_state_fraction,overlap_pairs_per_state,mean_penetration_over_r"
COLUMNS+=",max_penetration_over_r"

# ---- the study ------------------------------------------------------------------------------------
# First the physics of every scene and rung (equilibration, overlaps, measured runs); then the timing
# rounds; then one CSV row per scene and rung. Times are the step loop as the program reports it, per
# disk and time unit (K sub-steps count as one step), the best of the measured and timing runs: on a
# shared machine the least disturbed run is the closest to the cost itself.
LOAD_START=$(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo unknown)
START=$EPOCHREALTIME
: > "$OUTPUT.rows"
for eta in $FRACTIONS; do
    base=$TMP_DIR/eta$eta.in
    tools/gen "$N" --fraction "$eta" --speed "$SPEED" --steps 1 --seed "$SEED" > "$base" ||
        die "cannot generate the scene at eta = $eta"
    for rung in $RUNGS; do
        rung_command "$rung"
        tag=$TMP_DIR/eta$eta-$rung
        # equilibration, from the generated scene, with the rung's own dynamics
        with_header "$base" "$EQ_STEPS" perf > "$tag.in"
        run_prog "$tag.in" "$tag.out" "$tag.err" --dump17 --quiet
        state_input "$tag.out" "$base" > "$tag.eq.in"
        # the overlaps of the equilibrated dynamics, every step, as the program prints them
        with_header "$tag.eq.in" "$PRINT_STEPS" print > "$tag.in"
        run_prog "$tag.in" "$tag.out" "$tag.err" --quiet
        tools/measure --depth "$DEPTH" "$tag.in" "$tag.out" > "$tag.overlaps" ||
            die "tools/measure failed on $tag.out"
        # the measured runs, each from the last one's final state
        cp "$tag.eq.in" "$tag.next.in"
        : > "$tag.rows"
        : > "$tag.times"
        for ((b = 1; b <= BLOCKS; b++)); do
            with_header "$tag.next.in" "$BLOCK_STEPS" perf > "$tag.in"
            run_prog "$tag.in" "$tag.out" "$tag.err" --dump17 --pressure
            m=$(tools/measure "$tag.in" "$tag.out") || die "tools/measure failed on $tag.out"
            seconds=$(loop_seconds "$tag.err")
            pressure=$(sed -n 's/.*: pressure: .* P = \([0-9.e+-]*\)$/\1/p' "$tag.err" | tail -n 1)
            [ -n "$seconds" ] && [ -n "$pressure" ] || die "$PROG: no timing or pressure line: $(tail -n 2 "$tag.err")"
            echo "$pressure $(value energy_first "$m") $(value energy_last "$m") $(value pair_collisions "$m")" \
                "$(value wall_collisions "$m") $(value L "$m") $(value r "$m")" >> "$tag.rows"
            ns_per_step "$seconds" "$BLOCK_STEPS" >> "$tag.times"
            state_input "$tag.out" "$base" > "$tag.next.in"
        done
    done
done
# the timing rounds: every scene and rung once per round, so that the rounds spread over minutes and
# every rung meets the same load
for ((k = 1; k <= TIME_ROUNDS; k++)); do
    for eta in $FRACTIONS; do
        for rung in $RUNGS; do
            rung_command "$rung"
            tag=$TMP_DIR/eta$eta-$rung
            with_header "$tag.eq.in" "$TIME_STEPS" perf > "$tag.in"
            run_prog "$tag.in" /dev/null "$tag.err" --pressure
            seconds=$(loop_seconds "$tag.err")
            [ -n "$seconds" ] || die "$PROG: no timing line: $(tail -n 2 "$tag.err")"
            ns_per_step "$seconds" "$TIME_STEPS" >> "$tag.times"
        done
    done
done
for eta in $FRACTIONS; do
    k1_ns=nan
    [ ! -s "$TMP_DIR/eta$eta-k1.times" ] || k1_ns=$(sort -g "$TMP_DIR/eta$eta-k1.times" | head -n 1)
    for rung in $RUNGS; do
        rung_command "$rung"
        tag=$TMP_DIR/eta$eta-$rung
        awk -v OFS=, -v rung="$rung" -v prog="$(echo $PROG ${OPTS[*]})" -v n="$N" -v threads="$THREADS" \
            -v s="$BLOCK_STEPS" -v ov="$(cat "$tag.overlaps")" -v times="$(sort -g "$tag.times" | tr '\n' ' ')" \
            -v k1="$k1_ns" '
            function key(name,   m, k) { m = split(ov, f, " "); for (k = 1; k <= m; k++) if (index(f[k], name "=") == 1) return substr(f[k], length(name) + 2); return "nan" }
            {
                b++; L = $6; r = $7
                if (b == 1) e0 = $2
                kt = ($2 + $3) / (2 * n); z[b] = $1 * L * L / (n * kt)
                zs += z[b]; ps += $1; kts += kt; pc += $4; wc += $5
                d = ($3 - e0) / e0; if (d < 0) d = -d; if (d > drift) drift = d
            }
            END {
                zm = zs / b
                for (k = 1; k <= b; k++) var += (z[k] - zm) ^ 2
                se = sqrt(var / (b - 1) / b)
                eta = n * 3.141592653589793 * r * r / (L * L)
                zh = (1 + eta * eta / 8) / ((1 - eta) ^ 2)
                g = (zh - 1) / (2 * eta); kt = kts / b
                enskog = 2 * (2 * r) * (n / (L * L)) * g * sqrt(3.141592653589793 * kt)
                m = split(times, ns, " "); h = int((m + 1) / 2)
                med = m % 2 ? ns[h] : (ns[h] + ns[h + 1]) / 2
                t = b * s
                printf "%s,%s,%.6g,%d,%.10g,%.10g,%d,%d,%d,%.4g,%.4g,%.4g,%.6g,%.6g,%.5f,%.5f,%.5f,%.3f,%.3f,%.6g,%.6g,%.6g,%.6g,%.3g,%s,%s,%.4g,%.4g\n",
                    rung, prog, eta, n, L, r, threads, t, m, ns[1], med, k1 == "nan" ? -1 : ns[1] / k1, kt, ps / b,
                    zm, se, zh, 100 * (zm - zh) / zh, 100 * se / zh, pc / t, wc / t, pc / t / n * 2, enskog,
                    drift, key("overlap_state_fraction"), key("overlap_pairs_per_state"),
                    key("mean_penetration") / r, key("max_penetration") / r
            }' "$tag.rows" >> "$OUTPUT.rows"
        tail -n 1 "$OUTPUT.rows" | awk -F, '{ printf "accuracy.sh: eta %s %-6s Z = %s +- %s (Henderson %s, %+.2f%%), %s ns per particle-step (best of %s runs)\n", $3, $1, $15, $16, $17, $18, $10, $9 }' >&2
    done
done
{
    provenance
    echo "# load average at end (1, 5, 15 min): $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null)"
    echo "$COLUMNS"
    cat "$OUTPUT.rows"
} > "$OUTPUT.part"
rm -f "$OUTPUT.rows"
mv "$OUTPUT.part" "$OUTPUT"
echo "accuracy.sh: $OUTPUT written in $(awk -v a="$START" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.0f", b - a }') s" >&2

# ---- the table (REPORT.md) and the figure ---------------------------------------------------------
grep -v '^#' "$OUTPUT" | awk -F, '
    NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k
              print "| rung | eta | Z measured | Z Henderson | deviation % | overlap fraction | overlapping pairs per state | max penetration / r | energy drift | pair collisions per disk per time unit (Enskog) | wall collisions per time unit | ns per particle-step | time / K = 1 |"
              print "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"; next }
    { printf "| %s | %s | %.3f +- %.3f | %.3f | %+.2f +- %.2f | %.3g | %.4g | %.3g | %.2g | %.4f (%.4f) | %.4g | %.4g | %.2f |\n",
        $col["rung"], $col["eta"], $col["z"], $col["z_stderr"], $col["z_henderson"], $col["deviation_pct"],
        $col["deviation_stderr_pct"], $col["overlap_state_fraction"], $col["overlap_pairs_per_state"],
        $col["max_penetration_over_r"], $col["energy_drift"], $col["pair_collisions_per_disk_time"],
        $col["enskog_pair_collisions_per_disk_time"], $col["wall_collisions_per_time"],
        $col["min_ns_per_particle_step"], $col["time_over_k1"] }'
[ "$QUICK" = 1 ] || plot "$OUTPUT"
