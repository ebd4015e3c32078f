#!/usr/bin/env bash
# ./bench.sh plots: the figures of bench.sh summaries (make plots). For each NAME.summary.csv given (default:
# every bench/*.summary.csv) it writes beside it (with --merge NAME FILES...: one set NAME-*.png of the
# points of all the files, for a machine whose sweep ran in parts):
#   NAME-time.png     ns per particle-step against N, log-log, a panel per scene, a line per backend/threads
#   NAME-speedup.png  omp speedup over 1 thread against threads, a panel per scene, a line per N
#   NAME-gpu.png      cuda speedup over the fastest CPU run against N, a line per scene (cuda rows only)
# Every value is the best (min) of the timed runs of a point, per particle-step, since steps differ
# between points.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/../.."

command -v gnuplot >/dev/null 2>&1 || {
    echo "plot.sh: gnuplot not found (apt-get install gnuplot-nox)" >&2
    exit 1
}
if [ $# -eq 0 ]; then
    set -- bench/*.summary.csv
    [ -e "$1" ] || { echo "plot.sh: no bench/*.summary.csv (run ./bench.sh first)" >&2; exit 1; }
fi
TERMINAL=pngcairo
gnuplot -e "set terminal pngcairo" >/dev/null 2>&1 || TERMINAL=png
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# rows FILE: backend threads scene n ns_per_particle_step, one per point, whatever the column order.
rows() {
    grep -v '^#' "$1" | awk -F, '
        NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k; next }
        { print $col["backend"], $col["threads"], $col["scene"], $col["n"], $col["min_ns_per_particle_step"] }'
}

# layout COUNT: "rows cols width height" of a multiplot with COUNT panels.
layout() {
    local cols=$(($1 < 3 ? $1 : 3))
    local r=$((($1 + cols - 1) / cols))
    echo "$r $cols $((520 * cols)) $((400 * r))"
}

# scenes SERIES_FILE: the scenes in the order bench.sh runs them (first appearance).
scenes() { awk '{ print $3 }' "$1" | awk '!seen[$0]++'; }

# series label for a backend and its thread count
label() {
    case $1 in
        omp) [ "$2" = 1 ] && echo "omp, 1 thread" || echo "omp, $2 threads" ;;
        *) echo "$1" ;;
    esac
}

plot_time() {
    local data=$1 png=$2 title=$3 scenes rows cols w h scene all series b t f plots k
    scenes=$(scenes "$data")
    # one colour per backend/threads across all panels
    all=$(awk '{ print $1, $2 }' "$data" | awk '!seen[$0]++')
    read -r rows cols w h <<< "$(layout "$(echo "$scenes" | wc -l)")"
    {
        echo "set terminal $TERMINAL size $w,$h font ',10'"
        echo "set output '$png'"
        echo "set logscale xy; set grid; set key top left"
        echo "set xlabel 'N (particles)'; set ylabel 'ns per particle-step (min of runs)'"
        echo "set format x '10^{%T}'; set format y '10^{%T}'"
        echo "set multiplot layout $rows,$cols title '$title'"
        for scene in $scenes; do
            plots=""
            series=$(awk -v s="$scene" '$3 == s { print $1, $2 }' "$data" | awk '!seen[$0]++')
            while read -r b t; do
                f="$WORK/time-$scene-$b-$t"
                awk -v s="$scene" -v b="$b" -v t="$t" '$3 == s && $1 == b && $2 == t { print $4, $5 }' \
                    "$data" | sort -n > "$f"
                k=$(echo "$all" | grep -n -x "$b $t" | cut -d: -f1)
                plots="$plots${plots:+, }'$f' using 1:2 with linespoints linetype $k title '$(label "$b" "$t")'"
            done <<< "$series"
            echo "set title '$scene'"
            echo "plot $plots"
        done
        echo "unset multiplot"
    } > "$WORK/time.gp"
    gnuplot "$WORK/time.gp"
}

plot_speedup() {
    local data=$1 png=$2 title=$3 scenes rows cols w h scene plots n f maxt tics
    awk '$1 == "omp"' "$data" > "$WORK/omp"
    if [ "$(awk '{ print $2 }' "$WORK/omp" | sort -u | wc -l)" -lt 2 ]; then
        echo "plot.sh: $png skipped (fewer than 2 omp thread counts)" >&2
        return
    fi
    maxt=$(awk '{ print $2 }' "$WORK/omp" | sort -n | tail -n 1)
    tics=$(awk '{ print $2 }' "$WORK/omp" | sort -n -u | paste -s -d, -)
    scenes=$(scenes "$WORK/omp")
    read -r rows cols w h <<< "$(layout "$(echo "$scenes" | wc -l)")"
    {
        echo "set terminal $TERMINAL size $w,$h font ',10'"
        echo "set output '$png'"
        echo "set grid; set key top left; set logscale xy 2; set xrange [1:$maxt]"
        echo "set xtics ($tics); set ytics (0.125, 0.25, 0.5, $tics)"
        echo "set xlabel 'omp threads'; set ylabel 'speedup over 1 thread'"
        echo "set multiplot layout $rows,$cols title '$title'"
        for scene in $scenes; do
            plots="x with lines dashtype 2 linecolor 'gray' title 'ideal'"
            for n in $(awk -v s="$scene" '$3 == s { print $4 }' "$WORK/omp" | sort -n -u); do
                f="$WORK/speedup-$scene-$n"
                awk -v s="$scene" -v n="$n" '$3 == s && $4 == n { ns[$2] = $5 }
                    END { if (1 in ns) for (t in ns) print t, ns[1] / ns[t] }' "$WORK/omp" | sort -n > "$f"
                [ "$(wc -l < "$f")" -ge 2 ] || continue
                plots="$plots, '$f' using 1:2 with linespoints title 'N = $n'"
            done
            echo "set title '$scene'"
            echo "plot $plots"
        done
        echo "unset multiplot"
    } > "$WORK/speedup.gp"
    gnuplot "$WORK/speedup.gp"
}

plot_gpu() {
    local data=$1 png=$2 title=$3 scene plots="" f
    if ! awk '$1 == "cuda" { found = 1 } END { exit !found }' "$data"; then
        echo "plot.sh: $png skipped (no cuda rows)" >&2
        return
    fi
    for scene in $(awk '$1 == "cuda"' "$data" | scenes /dev/stdin); do
        f="$WORK/gpu-$scene"
        awk -v s="$scene" '$3 != s { next }
            $1 == "cuda" { gpu[$4] = $5; next }
            !($4 in cpu) || $5 < cpu[$4] { cpu[$4] = $5 }
            END { for (n in gpu) if (n in cpu) print n, cpu[n] / gpu[n] }' "$data" | sort -n > "$f"
        [ -s "$f" ] && plots="$plots${plots:+, }'$f' using 1:2 with linespoints title '$scene'"
    done
    if [ -z "$plots" ]; then
        echo "plot.sh: $png skipped (no N measured on both cuda and a CPU backend)" >&2
        return
    fi
    {
        echo "set terminal $TERMINAL size 720,480 font ',10'"
        echo "set output '$png'"
        echo "set logscale xy; set grid; set key top left; set format x '10^{%T}'"
        echo "set xlabel 'N (particles)'; set ylabel 'fastest CPU time / cuda time (per particle-step)'"
        echo "set title '$title'"
        echo "plot 1 with lines dashtype 2 linecolor 'gray' title 'break-even', $plots"
    } > "$WORK/gpu.gp"
    gnuplot "$WORK/gpu.gp"
}

# figures DATA NAME CSV: the three figures of the rows in DATA, titled by CSV's machine lines
figures() {
    local data=$1 name=$2 csv=$3 where gpu
    where=$(sed -n 's/^# cpu: \(.*\); cores: \(.*\)/\1, \2 cores/p' "$csv" | head -n 1)
    gpu=$(sed -n 's/^# gpu: \([^;]*\).*/\1/p' "$csv" | head -n 1)
    [ -z "$gpu" ] || [ "$gpu" = none ] || where="$where; $gpu"
    plot_time "$data" "$name-time.png" "Time per particle-step ($where)"
    plot_speedup "$data" "$name-speedup.png" "OpenMP speedup ($where)"
    plot_gpu "$data" "$name-gpu.png" "GPU over CPU ($where)"
}

if [ "$1" = --merge ]; then
    # --merge NAME A.summary.csv B.summary.csv ...: one set of figures NAME-*.png from the points of all
    # the files (sweeps of one machine run in parts); a point measured in several files is taken from
    # the last one given
    name=${2?--merge needs a name}
    shift 2
    for csv in "$@"; do
        [ -r "$csv" ] || { echo "plot.sh: cannot read $csv" >&2; exit 1; }
        rows "$csv"
    done | awk '{ key = $1 " " $2 " " $3 " " $4; if (!(key in row)) order[++k] = key; row[key] = $0 }
                END { for (i = 1; i <= k; i++) print row[order[i]] }' > "$WORK/data"
    figures "$WORK/data" "$name" "$1"
    echo "plot.sh: figures of $* written as $name-*.png" >&2
    exit 0
fi
for csv in "$@"; do
    [ -r "$csv" ] || { echo "plot.sh: cannot read $csv" >&2; exit 1; }
    name=${csv%.summary.csv}
    name=${name%.csv}
    rows "$csv" > "$WORK/data"
    [ -s "$WORK/data" ] || { echo "plot.sh: $csv has no rows" >&2; exit 1; }
    figures "$WORK/data" "$name" "$csv"
    echo "plot.sh: figures of $csv written as $name-*.png" >&2
done
