# omp against seq, byte for byte, on generated scenes that stress the broad phase and the choice of
# events: slow, fast (a quarter of the box per step), dense, dilute, overlapping, and scenes of 12000
# heavily overlapping disks that need several parallel rounds before the sequential finish, at 1, 2,
# 3 and 7 threads (and that fast_aside takes omp.c's choose_move, whose bytes it compares). Then --check
# (the broad phase against all pairs, every step) on scenes of a few thousand disks.
# The single-precision builds (seq_f32, omp_f32) go through the same scenes: their broad phase has its
# own rounding margins, and only these comparisons show they suffice.
GEN=tools/gen
D=$TMP/omp
mkdir -p "$D"

# name and tools/gen arguments, one scene a line
omp_scenes() { grep -v '^#' tests/omp_scenes.txt; }

SUF=""     # program suffix: "" for the double build, _f32 for the float one
omp_compare() { # name input [extra options]; REF: seq's output already made, not made again
    local name=$1$SUF in=$2
    shift 2
    if [ -n "${REF:-}" ]; then
        cp "$REF" "$D/$name.ref"
    elif ! ./seq$SUF "$in" --quiet "$@" > "$D/$name.ref" 2> "$D/err"; then
        fail "omp/$name seq" "$(head -c 300 "$D/err")"
        return
    fi
    local bad
    bad=$(threads_mismatch "${OMP_THREAD_COUNTS:-1 2 3 7}" "$D/$name.ref" ./omp$SUF "$in" --quiet "$@")
    if [ -z "$bad" ]; then
        pass "omp$SUF/$name same bytes as seq$SUF at ${OMP_THREAD_COUNTS:-1 2 3 7} threads"
    else
        fail "omp$SUF/$name" "$bad"
    fi
}

# The quick suite leaves out the scenes whose seq run takes seconds (12000 disks) but rounds_print, and
# the float build above 1000 disks.
while read -r name args; do
    n=${args%% *}
    if ! all_suite && [ "$n" -gt 5000 ] && [ "$name" != rounds_print ]; then continue; fi
    # shellcheck disable=SC2086
    $GEN $args > "$D/$name.in"
    omp_compare "$name" "$D/$name.in"
    if all_suite || [ "$n" -le 1000 ]; then SUF=_f32 omp_compare "$name" "$D/$name.in"; fi
done < <(omp_scenes)
# shellcheck disable=SC2046
[ -f "$D/fast_aside.in" ] || $GEN $(omp_scenes | awk '$1 == "fast_aside" { $1 = ""; print }') > "$D/fast_aside.in"

# the assignment's own random scene (no particle lines), and %.17g output
printf '300\n400\n1\n15\nprint\n' > "$D/random.in"
omp_compare random "$D/random.in" --seed 7
SUF=_f32 omp_compare random "$D/random.in" --seed 7
omp_compare dump17 "$D/overlap_print.in" --dump17
REF=$D/rounds_print.ref OMP_THREAD_COUNTS="4 5 6 8 9 10 11 12 13 14 15 16" omp_compare rounds_threads "$D/rounds_print.in"

# fast_aside's steps on 2 and 3 threads choose on one thread while the others move (omp.c's
# choose_move): the comparison above covers that path only if the steps take it
for t in 2 3; do
    if ./omp "$D/fast_aside.in" --quiet --threads "$t" --stats 2>&1 > /dev/null |
        grep -q 'beside the moves in 4 of 4 steps'; then
        pass "omp/fast_aside: the choice beside the moves in every step at $t threads"
    else
        fail "omp/fast_aside: the choice beside the moves at $t threads" "--stats counts fewer steps"
    fi
done

# --check: the broad phase must find every event all pairs find (the quick suite: two of the scenes)
check_scenes=("3000 --assignment --L 3000 --steps 3" "2000 --r 1e-6 --L 1 --speed 1e5 --steps 3")
all_suite && check_scenes+=("4000 --fraction 0.3 --speed 0.5 --steps 4" \
    "3000 --r 0.01 --L 300 --speed 3000 --steps 3" "4000 --fraction 0.7 --overlap --speed 2 --steps 3")
for args in "${check_scenes[@]}"; do
    # shellcheck disable=SC2086
    $GEN $args > "$D/check.in"
    for prog in omp omp_f32; do
        if ./$prog "$D/check.in" --quiet --check --threads 2 > /dev/null 2> "$D/err"; then
            pass "$prog --check: $args"
        else
            fail "$prog --check: $args" "$(head -c 300 "$D/err")"
        fi
    done
done

# The float build places random disks within its own speed limit (|v| <= 1e9), even where the
# assignment's speeds L/(8r) would exceed it
printf '50\n1e9\n1e-3\n0\nperf\n' > "$D/f32_fast.in"
if ./seq_f32 "$D/f32_fast.in" --quiet --dump17 > "$D/out" 2> "$D/err" &&
    awk 'NF >= 6 { rows++; for (k = 5; k <= 6; k++) if ($k > 1e9 || $k < -1e9) bad = 1 }
        END { exit bad || rows != 100 }' "$D/out"; then
    pass "seq_f32 random placement keeps |v| <= 1e9"
else
    fail "seq_f32 random placement keeps |v| <= 1e9" "$(head -c 200 "$D/err")"
fi

# a team smaller than asked for (OMP_THREAD_LIMIT, OMP_DYNAMIC) starts and runs all the same
printf '1000\n20000\n1\n20\nperf\n' > "$D/limit.in"
./seq "$D/limit.in" > "$D/limit.ref" 2> /dev/null
for env_limit in OMP_THREAD_LIMIT=1 OMP_DYNAMIC=true; do
    env "$env_limit" timeout 60 ./omp "$D/limit.in" --threads 4 > "$D/limit.out" 2> "$D/err"
    limit_rc=$? # 124: it did not finish within a minute
    if [ "$limit_rc" -eq 0 ] && cmp -s "$D/limit.ref" "$D/limit.out"; then
        pass "omp --threads 4 under $env_limit: seq's bytes"
    else
        fail "omp --threads 4 under $env_limit" "exit $limit_rc, $(cmp "$D/limit.ref" "$D/limit.out" 2>&1 | head -c 100) $(head -c 200 "$D/err")"
    fi
done

# omp_team.c moves each thread of the team to a core of its own at the start, then widens its mask
# again: while a run is under way, every thread may run on every core the process may
if [ "$(nproc)" -ge 2 ] && [ -d /proc/self/task ]; then
    printf '100000\n20000\n1\n200\nperf\n' > "$D/team.in"
    ./omp "$D/team.in" --threads 2 > /dev/null 2>&1 &
    pid=$!
    for _ in $(seq 100); do
        [ "$(ls "/proc/$pid/task" 2> /dev/null | wc -l)" -ge 2 ] && break
        sleep 0.05
    done
    sleep 0.2
    want=$(awk '/Cpus_allowed_list/ { print $2 }' "/proc/$pid/status" 2> /dev/null)
    masks=$(cat /proc/"$pid"/task/*/status 2> /dev/null | awk '/Cpus_allowed_list/ { print $2 }' | sort | uniq -c)
    kill "$pid" 2> /dev/null
    wait "$pid" 2> /dev/null
    if [ -n "$want" ] && [ "$(echo "$masks" | wc -l)" = 1 ] && [ "$(echo "$masks" | awk '{ print $1, $2 }')" = "2 $want" ]; then
        pass "omp's 2 threads free to run on the process's cores ($want) during a run"
    else
        fail "omp's threads free to run on the process's cores" "process $want; threads: $(echo $masks)"
    fi
else
    skip "omp's threads free to run on the process's cores" "one core, or no /proc"
fi
