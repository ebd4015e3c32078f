# cuda against seq, byte for byte, on generated scenes that stress the broad phase: slow and fast disks
# (one time slice and many), dense, dilute, overlapping starts, walls, the assignment's random scenes,
# mixed scenes (a few fast disks among slow ones), tiny radii, speeds far beyond the box, a few disks,
# speeds spread over all the speed levels (cuda_state.cuh, disk_level) with many slices.
# Each scene runs in print and perf mode, in double (cuda against seq) and in single precision
# (cuda_f32 against seq_f32: its broad phase has its own rounding margins). Without a GPU every case
# is a SKIP.
cuda_scenes() {
    echo "slow       tools/gen 2000 --fraction 0.2 --speed 0.5 --steps 40 --seed 3"
    echo "medium     tools/gen 1500 --fraction 0.2 --speed 20 --steps 30 --seed 4"
    echo "fast       tools/gen 1200 --assignment --fraction 0.05 --steps 30 --seed 5"
    echo "dense      tools/gen 1500 --fraction 0.45 --speed 1 --steps 40 --seed 6"
    echo "dilute     tools/gen 300 --fraction 0.001 --speed 40 --steps 40 --seed 7"
    echo "overlap    tools/gen 800 --overlap --fraction 0.5 --speed 1 --steps 30 --seed 8"
    echo "walls      tools/gen 40 --fraction 0.3 --speed 3 --steps 300 --seed 9"
    echo "random     printf 2000\n20000\n1\n20\nperf\n"
    echo "random_r5  printf 700\n3000\n5\n25\nperf\n"
    echo "fast_walls tools/gen 300 --assignment --L 150 --steps 20"
    echo "fast_mid   tools/gen 2000 --assignment --L 6000 --steps 10"
    echo "mixed_gas  tools/gen 4000 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 8"
    echo "mixed_dil  tools/gen 1500 --fraction 0.02 --speed 2 --fast 0.05 --fast-speed 0.5 --steps 12"
    echo "tiny_r     tools/gen 1000 --r 1e-4 --L 10 --speed 5e4 --fast 0.1 --steps 10"
    echo "huge_speed tools/gen 200 --fraction 0.1 --speed 1e7 --steps 10"
    echo "three_fast tools/gen 3 --assignment --L 30 --steps 30"
    echo "dense_fast tools/gen 3000 --assignment --L 2000 --overlap --steps 6"
    echo "spread     tools/gen 3000 --fraction 0.05 --speed 200 --steps 15 --seed 12"
}
# scene_input NAME CMD: the scene's input into $TMP/cuda_NAME.in, from CMD (a tools/gen command, or
# "printf FORMAT" for a literal input); non-zero if CMD fails
scene_input() {
    if [ "${2%% *}" = printf ]; then
        # shellcheck disable=SC2059
        printf "${2#printf }" > "$TMP/cuda_$1.in"
    else
        $2 > "$TMP/cuda_$1.in"
    fi
}
# (the quick suite: every scene in print mode, and in perf and single precision every other one)
k=0
while read -r name cmd; do
    k=$((k + 1))
    full=1
    if ! all_suite && [ $((k % 2)) = 0 ]; then full=0; fi
    if ! have_gpu; then
        for suf in "" _f32; do
            skip "cuda$suf/$name print" "no GPU"
            skip "cuda$suf/$name perf" "no GPU"
        done
        continue
    fi
    if ! scene_input "$name" "$cmd"; then
        fail "cuda/$name" "cannot generate the scene"
        continue
    fi
    for suf in "" _f32; do
        if [ ! -x "./cuda$suf" ]; then
            skip "cuda$suf/$name" "./cuda$suf not built"
            continue
        fi
        for mode in print perf; do
            sed "5s/.*/$mode/" "$TMP/cuda_$name.in" > "$TMP/cuda_${name}_$mode.in"
            ./seq$suf "$TMP/cuda_${name}_$mode.in" --quiet > "$TMP/cuda${suf}_${name}_$mode.expected"
            if [ "$full" = 0 ] && { [ -n "$suf" ] || [ "$mode" = perf ]; }; then continue; fi
            same_bytes "cuda$suf/$name $mode" "$TMP/cuda${suf}_${name}_$mode.expected" \
                ./cuda$suf "$TMP/cuda_${name}_$mode.in" --quiet
        done
    done
done <<< "$(cuda_scenes)"

# Paths that ordinary runs take rarely. SIM_CUDA_PLAN_SPEED plans for a fraction of the known speed
# ("0.5"), or alternates by batch ("0,1": plans of one slice between plans of several), so each step's
# gate must fit the grid to disks faster than planned; SIM_CUDA_EVENTS=2 starts with an event list of 2
# events, so steps overflow it, are refused while batches of other plans are in flight, and run again
# from the last committed state. The bytes stay seq's, and --stats must report both paths, or the case
# tested nothing.
# (the quick suite: two of the scenes, here and in the matrices below)
pick() { if all_suite; then echo "$1"; else echo "$2"; fi; }
for name in $(pick "slow fast overlap walls random" "fast walls"); do
    for mode in print perf; do
        for speed in 0.5 0,1; do
            label="cuda/$name $mode, plans at $speed of the speed, refused steps"
            if ! have_gpu; then
                skip "$label" "no GPU"
                continue
            fi
            same_bytes "$label" "$TMP/cuda_${name}_$mode.expected" env SIM_CUDA_PLAN_SPEED=$speed \
                SIM_CUDA_EVENTS=2 ./cuda "$TMP/cuda_${name}_$mode.in" --quiet --stats
            line=$(grep 'steps faster than planned' "$TMP/err")
            if [[ $line =~ \ ([0-9]+)\ steps\ faster\ than\ planned\;\ ([0-9]+)\ steps\ refused ]] &&
                [ "${BASH_REMATCH[1]}" -gt 0 ] && [ "${BASH_REMATCH[2]}" -gt 0 ]; then
                pass "$label: both paths taken"
            else
                fail "$label: both paths taken" "stats: ${line:-no line}"
            fi
        done
    done
done

# Batches of BATCH steps of one slice run as one CUDA graph unless --stats (cuda_launch.cuh, batch_launch),
# as the perf cases above do (steps of several slices launch kernel by kernel): here every batch kernel by
# kernel (SIM_CUDA_GRAPH=0), and in graphs through refused steps and plans that alternate between one
# slice and several, which change the graphs' shape (the event list of 2 overflows on these scenes: the
# --stats cases above count the refusals; without --stats the graphs stay on). Each kernel of a step
# starts launching while the one before it drains (programmatic dependent launch, cuda_launch.cuh
# step_kernel) unless SIM_CUDA_PDL=0, as in the last case.
for name in $(pick "fast random dense spread" "random spread"); do
    for what in "kernel by kernel" "graphs, refused steps" "graphs, no programmatic launches"; do
        label="cuda/$name perf, $what"
        if ! have_gpu; then
            skip "$label" "no GPU"
            continue
        fi
        envs="SIM_CUDA_GRAPH=0"
        [ "$what" = "graphs, refused steps" ] && envs="SIM_CUDA_EVENTS=2 SIM_CUDA_PLAN_SPEED=0,1"
        [ "$what" = "graphs, no programmatic launches" ] && envs="SIM_CUDA_PDL=0 SIM_CUDA_EVENTS=2"
        same_bytes "$label" "$TMP/cuda_${name}_perf.expected" env $envs ./cuda "$TMP/cuda_${name}_perf.in" --quiet
    done
done

# The cell table's exclusive sum: two short kernels that also clear the counts behind them, or cub's
# for long tables, after which the counts are cleared before the next binning (cuda.cu,
# bin_place_launch). These scenes' tables are short; SIM_CUDA_SCAN_TILES=-1 sends every other batch to
# cub, so the short scans also follow cub's, in graphs and (with SIM_CUDA_WINDOW=1) across windows (a gas's
# keyed steps in those batches sort their tables in buckets instead, cuda_rows.cuh; its gathering steps
# take cub's). --stats counts the tables each way: both must have been taken.
for name in $(pick "slow fast walls random spread mixed_gas" "slow spread"); do
    for mode in print perf; do
        label="cuda/$name $mode, cell tables scanned short and by cub in turn"
        if ! have_gpu; then
            skip "$label" "no GPU"
            skip "$label, windows from 1 slice" "no GPU"
            continue
        fi
        same_bytes "$label" "$TMP/cuda_${name}_$mode.expected" env SIM_CUDA_SCAN_TILES=-1 \
            ./cuda "$TMP/cuda_${name}_$mode.in" --quiet
        same_bytes "$label, windows from 1 slice" "$TMP/cuda_${name}_$mode.expected" env SIM_CUDA_SCAN_TILES=-1 \
            SIM_CUDA_WINDOW=1 ./cuda "$TMP/cuda_${name}_$mode.in" --quiet --stats
        line=$(grep "cell tables scanned" "$TMP/err")
        if [[ $line =~ short\ kernels:\ ([0-9]+),\ by\ cub:\ ([0-9]+) ]] && [ "${BASH_REMATCH[1]}" -gt 0 ] &&
            [ "${BASH_REMATCH[2]}" -gt 0 ]; then
            pass "$label: both ways taken"
        else
            fail "$label: both ways taken" "stats: ${line:-no line}"
        fi
    done
done

# Steps of one slice: a move keys the disks' cells for the next step of its batch (cuda_move.cuh, MoveBin) on
# cells fitted to SIM_CUDA_BIN_AHEAD times its speed, and a step whose speed outgrew them bins anew. At 1
# (no room) the speeds of these scenes, which grow as collisions spread them, send steps both ways:
# --stats counts the steps each way, and both must have been taken. Then the same in graphs, through
# refused steps and with cub's scans every other batch, and with no keys ahead (0). (Perf mode: print
# mode's batches end at each step printed, one step here.)
for name in $(pick "slow dense overlap" "slow dense"); do
    label="cuda/$name perf, keyed by the move before or binned anew"
    if ! have_gpu; then
        for what in "" ", in graphs, refused steps, cub's scans" ", no keys ahead"; do skip "$label$what" "no GPU"; done
        continue
    fi
    expected=$TMP/cuda_${name}_perf.expected
    same_bytes "$label" "$expected" env SIM_CUDA_BIN_AHEAD=1 ./cuda "$TMP/cuda_${name}_perf.in" --quiet --stats
    line=$(grep "keyed by the move before" "$TMP/err")
    if [[ $line =~ before\ them:\ ([0-9]+),\ binned\ anew.*:\ ([0-9]+) ]] && [ "${BASH_REMATCH[1]}" -gt 0 ] &&
        [ "${BASH_REMATCH[2]}" -gt 0 ]; then
        pass "$label: both ways taken"
    else
        fail "$label: both ways taken" "stats: ${line:-no line}"
    fi
    same_bytes "$label, in graphs, refused steps, cub's scans" "$expected" env SIM_CUDA_BIN_AHEAD=1 \
        SIM_CUDA_EVENTS=2 SIM_CUDA_SCAN_TILES=-1 ./cuda "$TMP/cuda_${name}_perf.in" --quiet
    same_bytes "$label, no keys ahead" "$expected" env SIM_CUDA_BIN_AHEAD=0 ./cuda "$TMP/cuda_${name}_perf.in" --quiet
done

# A batch keys the next batch's first step where that batch runs on the last gather (cuda.cu, keyed_on: it
# ends within GATHER_SPAN, 17, steps of that gather, unless gathering at its start serves the rest of the
# run): print mode's batches of one step then gather at 1, 18 and 24 of 40 steps, 37 steps keyed, not
# nearly every step; a perf run of 20 steps (batches 1, 2-9, 10-17 and 18-20) gathers at 1 and 10, not at
# 18 for 3 steps. The bytes stay seq's; other counts would mean the batches gather more often or too
# seldom. The counts follow from the batches' extents alone, which no refused step may change here.
for run in "slow print 40 37" "slow perf 20 18"; do
    read -r name mode steps want <<< "$run"
    label="cuda/$name $mode, $steps steps: batches keyed by the batch before"
    if ! have_gpu; then
        skip "$label" "no GPU"
        continue
    fi
    in=$TMP/cuda_${name}_${mode}_$steps.in
    sed "4s/.*/$steps/" "$TMP/cuda_${name}_$mode.in" > "$in"
    ./seq "$in" --quiet > "$in.expected"
    same_bytes "$label" "$in.expected" ./cuda "$in" --quiet --stats
    line=$(grep "keyed by the move before" "$TMP/err")
    # a keyed step whose disks outgrew the cells they were keyed on bins anew: both came after a move that keyed
    refused=$(grep -o '[0-9]* steps refused' "$TMP/err")
    if [[ $line =~ before\ them:\ ([0-9]+),\ binned\ anew.*:\ ([0-9]+) ]] &&
        [ $((BASH_REMATCH[1] + BASH_REMATCH[2])) -eq "$want" ] && [ "$refused" = "0 steps refused" ]; then
        pass "$label: $want of $steps steps keyed"
    else
        fail "$label: $want of $steps steps keyed, none refused" "stats: ${line:-no line}; ${refused:-no count refused}"
    fi
done

# Steps of one slice settle the pair events that are the only one of both their disks before the choice's
# rounds (cuda_choose.cuh, settle_kernel) where a disk has few events a step; SIM_CUDA_SETTLE sets how few.
# Every step settles at 1e30 and none at 0, and both print seq's bytes; --stats counts the events the steps
# that settle found and those they left to the rounds, and both the settled and the contested must be some.
# Then in graphs through refused steps.
for name in $(pick "slow dense overlap" "slow dense"); do
    label="cuda/$name perf, events settled before the rounds"
    if ! have_gpu; then
        for what in "" ", in graphs, refused steps" ", never"; do skip "$label$what" "no GPU"; done
        continue
    fi
    expected=$TMP/cuda_${name}_perf.expected
    same_bytes "$label" "$expected" env SIM_CUDA_SETTLE=1e30 ./cuda "$TMP/cuda_${name}_perf.in" --quiet --stats
    line=$(grep "of them to the rounds" "$TMP/err")
    if [[ $line =~ found\ ([0-9]+)\ pair\ events\ and\ left\ ([0-9]+)\ of ]] &&
        [ "${BASH_REMATCH[1]}" -gt "${BASH_REMATCH[2]}" ] && [ "${BASH_REMATCH[2]}" -gt 0 ]; then
        pass "$label: some settled, some contested"
    else
        fail "$label: some settled, some contested" "stats: ${line:-no line}"
    fi
    same_bytes "$label, in graphs, refused steps" "$expected" env SIM_CUDA_SETTLE=1e30 SIM_CUDA_EVENTS=2 \
        ./cuda "$TMP/cuda_${name}_perf.in" --quiet
    same_bytes "$label, never" "$expected" env SIM_CUDA_SETTLE=0 ./cuda "$TMP/cuda_${name}_perf.in" --quiet --stats
    if grep -q "of them to the rounds" "$TMP/err"; then
        fail "$label, never: no step settles" "stats: $(grep "of them to the rounds" "$TMP/err")"
    else
        pass "$label, never: no step settles"
    fi
done

# Time windows (cuda_state.cuh, window_start): a step's slices are cut into windows whose choice is made one
# after another, disks taken leaving the later windows. A scene gets them only when it has disks enough
# to fill the device (about 1e6 entries a window), so here SIM_CUDA_WINDOW forces the first window's
# slices: 1 gives the most windows, 3 windows of 3, 6, 12... slices. --stats must list the windows,
# or the case tested nothing. With SIM_CUDA_EVENTS=2 a later window's events overflow the list too;
# with SIM_CUDA_PLAN_SPEED as well, the device's slices and windows differ from the plan's, or plans of
# one slice alternate with windowed ones, while refused steps run again.
# (F = 3 and the plans: the scenes whose steps have more than 3 slices; random_r5 and fast_walls have 2
# or 3.) Speed levels take windows whose first slice is a multiple of their slices' length: F = 2 and 4
# allow 2 and 3 levels, on the scene whose 8 to 11 slices hold every level (spread).
for name in $(pick "fast random random_r5 fast_walls fast_mid mixed_gas mixed_dil tiny_r dense_fast spread" \
    "random fast_walls spread"); do
    for run in "1 print" "1 perf" "3 perf" "1 perf f32" "1 print refused" "1 print plan0.5" "1 perf plan0,1" \
        "2 perf" "4 print" "2 perf f32" "4 perf refused"; do
        read -r F mode what <<< "$run"
        if { [ "$F" = 3 ] || [ "${what#plan}" != "$what" ]; } &&
            { [ "$name" = random_r5 ] || [ "$name" = fast_walls ]; }; then continue; fi
        if { [ "$F" = 2 ] || [ "$F" = 4 ]; } && [ "$name" != spread ]; then continue; fi
        suf="" envs="SIM_CUDA_WINDOW=$F"
        [ "$what" = f32 ] && suf=_f32
        [ "$what" = refused ] && envs="$envs SIM_CUDA_EVENTS=2"
        [ "${what#plan}" != "$what" ] && envs="$envs SIM_CUDA_EVENTS=2 SIM_CUDA_PLAN_SPEED=${what#plan}"
        note=$what
        [ "${what#plan}" != "$what" ] && note="plans at ${what#plan} of the speed, refused steps"
        label="cuda$suf/$name $mode, windows from $F slice(s)${note:+ ($note)}"
        if ! have_gpu || [ ! -x "./cuda$suf" ]; then
            skip "$label" "no GPU"
            continue
        fi
        same_bytes "$label" "$TMP/cuda${suf}_${name}_$mode.expected" env $envs ./cuda$suf \
            "$TMP/cuda_${name}_$mode.in" --quiet --stats
        if grep -q 'per window, disks free' "$TMP/err"; then
            pass "$label: windows used"
        else
            fail "$label: windows used" "no window line in --stats"
        fi
    done
done

# SIM_CUDA_ROUNDS sets the grid-wide rounds of the choice (adapted to the events found otherwise): one
# leaves the one-block finish nearly all the events, eight run to the last
for name in $(pick "dense overlap random dense_fast" "dense dense_fast"); do
    for rounds in 1 8; do
        label="cuda/$name perf, $rounds grid-wide choice rounds"
        if ! have_gpu; then
            skip "$label" "no GPU"
            continue
        fi
        same_bytes "$label" "$TMP/cuda_${name}_perf.expected" env SIM_CUDA_ROUNDS=$rounds \
            ./cuda "$TMP/cuda_${name}_perf.in" --quiet
    done
done

# --substeps K: cuda runs the K sub-steps of each step and hands out whole steps, like seq
for name in $(pick "slow fast walls random" "fast walls"); do
    for k in 2 4; do
        if ! have_gpu; then
            skip "cuda/$name --substeps $k" "no GPU"
            continue
        fi
        in=$TMP/cuda_${name}_print.in
        ./seq "$in" --quiet --substeps $k > "$TMP/cuda_${name}_sub$k.expected"
        same_bytes "cuda/$name print --substeps $k" "$TMP/cuda_${name}_sub$k.expected" \
            ./cuda "$in" --quiet --substeps $k
    done
done

# Steps of several slices place each entry's slot and midpoint with its key below PLACE_FUSED_N disks
# (every scene above), else gather them in cell order after placing (cuda_launch.cuh, place_fused): here the
# gather, forced by SIM_CUDA_FUSED_N=0, on scenes of several slices, and with windows and speed levels.
for name in $(pick "fast random fast_mid mixed_gas tiny_r dense_fast spread" "random spread"); do
    for run in "print" "perf" "perf windows"; do
        read -r mode what <<< "$run"
        label="cuda/$name $mode, entries gathered after placement${what:+, windows from 1 slice}"
        if ! have_gpu; then
            skip "$label" "no GPU"
            continue
        fi
        envs="SIM_CUDA_FUSED_N=0"
        [ -n "$what" ] && envs="$envs SIM_CUDA_WINDOW=1"
        same_bytes "$label" "$TMP/cuda_${name}_$mode.expected" env $envs ./cuda "$TMP/cuda_${name}_$mode.in" --quiet
    done
done

# Scenes larger than the move's one wave of threads (MOVE_LOOP blocks a multiprocessor of THREADS each,
# some 1.4e5 on an H100), whose threads then move several disks in turns, and a random scene placed both
# ways. omp stands for seq here (t_70 holds it to seq's bytes): seq's cost a step grows with N squared.
big_scenes() {
    echo "big_gas      tools/gen 300000 --fraction 0.2 --speed 0.5 --steps 10 --seed 31"
    echo "big_dense    tools/gen 300000 --fraction 0.45 --speed 1 --steps 6 --seed 32"
    echo "big_random   printf 300000\n20000\n1\n4\nperf\n"
}
while read -r name cmd; do
    if ! have_gpu || [ ! -x ./omp ]; then
        skip "cuda/$name perf" "$(have_gpu && echo "./omp not built" || echo "no GPU")"
        continue
    fi
    if ! scene_input "$name" "$cmd"; then
        fail "cuda/$name" "cannot generate the scene"
        continue
    fi
    ./omp "$TMP/cuda_$name.in" --quiet > "$TMP/cuda_$name.expected"
    same_bytes "cuda/$name perf" "$TMP/cuda_$name.expected" ./cuda "$TMP/cuda_$name.in" --quiet
    if [ "$name" = big_random ]; then
        same_bytes "cuda/$name perf, entries gathered after placement" "$TMP/cuda_$name.expected" \
            env SIM_CUDA_FUSED_N=0 ./cuda "$TMP/cuda_$name.in" --quiet
    fi
done <<< "$(big_scenes)"

# The periodic box (--periodic, SPEC.md 7): the cells and the differences between disks wrap (cuda_detect.cuh,
# edge_runs), one cell a side or at least three; steps of one slice and of several (one speed level),
# time windows, sub-steps, random placement, a crystal near close packing, single precision.
periodic_scenes() {
    echo "p_gas      tools/gen 2000 --periodic --fraction 0.3 --speed 0.5 --steps 40 --seed 21"
    echo "p_dense    tools/gen 1500 --periodic --fraction 0.5 --speed 1 --steps 30 --seed 22"
    echo "p_fast     tools/gen 1200 --periodic --assignment --fraction 0.05 --steps 20 --seed 23"
    echo "p_one_cell tools/gen 6 --periodic --L 9 --speed 3 --steps 80 --seed 24"
    echo "p_three    tools/gen 30 --periodic --L 14 --speed 2 --steps 60 --seed 25"
    echo "p_crystal  tools/gen 780 --lattice --fraction 0.85 --speed 0.3 --steps 30 --seed 26"
    echo "p_random   printf 1500\n20000\n1\n20\nperf\n"
}
while read -r name cmd; do
    runs="print perf f32 windows substeps"
    all_suite || runs="print f32 windows"
    if ! have_gpu; then
        for run in $runs; do skip "cuda/$name --periodic $run" "no GPU"; done
        continue
    fi
    if ! scene_input "$name" "$cmd"; then
        fail "cuda/$name --periodic" "cannot generate the scene"
        continue
    fi
    for run in $runs; do
        mode=print suf="" envs="" extra=""
        case $run in perf) mode=perf ;; f32) suf=_f32 ;; windows) mode=perf envs="SIM_CUDA_WINDOW=1" ;;
            substeps) extra="--substeps 2" ;; esac
        if [ ! -x "./cuda$suf" ] || [ ! -x "./seq$suf" ]; then
            skip "cuda$suf/$name --periodic $run" "./cuda$suf or ./seq$suf not built"
            continue
        fi
        sed "5s/.*/$mode/" "$TMP/cuda_$name.in" > "$TMP/cuda_${name}_$run.in"
        # shellcheck disable=SC2086
        ./seq$suf "$TMP/cuda_${name}_$run.in" --quiet --periodic $extra > "$TMP/cuda_${name}_$run.expected"
        # shellcheck disable=SC2086
        same_bytes "cuda$suf/$name --periodic $run" "$TMP/cuda_${name}_$run.expected" \
            env $envs ./cuda$suf "$TMP/cuda_${name}_$run.in" --quiet --periodic $extra
    done
done <<< "$(periodic_scenes)"

# A keyed step's table sorted a bucket of a row's cells at a time (cuda_rows.cuh), which ordinary runs do where
# cub would scan it, as these scenes' short tables never are: SIM_CUDA_ROWS=1 sorts every keyed step's table so,
# in perf and print mode, in the periodic box and in single precision; then in graphs, through refused steps
# (SIM_CUDA_EVENTS=2) and steps binned anew (SIM_CUDA_BIN_AHEAD=1, counting nothing). --stats counts the tables
# sorted so, which must be some.
# (The periodic scenes' "windows" input is a perf run, as the quick suite writes it.)
for run in "slow perf" "slow print" "dense perf" "p_gas windows --periodic" "p_gas print --periodic" \
    "p_dense windows --periodic"; do
    read -r name mode extra <<< "$run"
    label="cuda/$name $mode${extra:+ $extra}, keyed tables sorted in buckets"
    if ! have_gpu; then
        skip "$label" "no GPU"
        continue
    fi
    in=$TMP/cuda_${name}_$mode.in expected=$TMP/cuda_${name}_$mode.expected
    # shellcheck disable=SC2086
    same_bytes "$label" "$expected" env SIM_CUDA_ROWS=1 ./cuda "$in" --quiet --stats $extra
    line=$(grep "sorted in buckets" "$TMP/err")
    if [[ $line =~ sorted\ in\ buckets:\ ([0-9]+) ]] && [ "${BASH_REMATCH[1]}" -gt 0 ]; then
        pass "$label: ${BASH_REMATCH[1]} tables"
    else
        fail "$label: some tables" "stats: ${line:-no line}"
    fi
    # shellcheck disable=SC2086
    same_bytes "$label, in graphs, refused steps, binned anew" "$expected" env SIM_CUDA_ROWS=1 SIM_CUDA_EVENTS=2 \
        SIM_CUDA_BIN_AHEAD=1 ./cuda "$in" --quiet $extra
    if [ -z "$extra" ] && [ -x ./cuda_f32 ]; then
        same_bytes "$label, single precision" "$TMP/cuda_f32_${name}_$mode.expected" env SIM_CUDA_ROWS=1 \
            ./cuda_f32 "$in" --quiet
    fi
done

# 8-bit cell counts (count_add): where cub scans the table of a step of one slice (SIM_CUDA_SCAN_TILES=0
# sends every table there), a cell of more than 255 disks refuses its step, which runs again counting in
# 32 bits. "point" (crowd_scene, tests/lib.sh): 300 of 1500 disks start on one point (the first step, alone
# in its batch, crowded);
# "ring": 1200 of 2700 tiny disks converge on one point, in perf and print mode (a step inside a batch,
# keyed by the move before it, in graphs without --stats). The bytes stay seq's, --stats names the crowded
# cell, and the slow gas, counted in 8 bits throughout, refuses nothing. Each run is timed out: a fallback
# that never took would refuse the same step forever.
label="cuda: 8-bit cell counts"
if have_gpu; then
    for run in "point perf" "ring perf" "ring print"; do
        read -r name mode <<< "$run"
        in=$TMP/cuda_crowd_${name}_$mode.in
        crowd_scene "$name" "$mode" > "$in"
        ./seq "$in" --quiet > "$in.expected"
        same_bytes "$label, $name $mode" "$in.expected" env SIM_CUDA_SCAN_TILES=0 timeout 120 ./cuda "$in" --quiet
        same_bytes "$label, $name $mode, --stats" "$in.expected" env SIM_CUDA_SCAN_TILES=0 timeout 120 \
            ./cuda "$in" --quiet --stats
        if grep -q "one for a cell past 255 disks" "$TMP/err"; then
            pass "$label, $name $mode: the crowded cell's step refused, then 32 bits"
        else
            fail "$label, $name $mode: the crowded cell's step refused" "stats: $(grep refused "$TMP/err")"
        fi
    done
    same_bytes "$label, point, 32 bits throughout" "$TMP/cuda_crowd_point_perf.in.expected" env SIM_CUDA_SCAN_TILES=0 \
        SIM_CUDA_NARROW=0 timeout 120 ./cuda "$TMP/cuda_crowd_point_perf.in" --quiet
    # a bucket of a keyed step's table (cuda_rows.cuh; SIM_CUDA_ROWS=1 on this short table of 32-bit counts) past
    # its room: the step refused, then tables counted cell by cell
    same_bytes "$label, ring perf, a bucket past its room" "$TMP/cuda_crowd_ring_perf.in.expected" \
        env SIM_CUDA_ROWS=1 timeout 120 ./cuda "$TMP/cuda_crowd_ring_perf.in" --quiet --stats
    if grep -q "one for a bucket past its room" "$TMP/err"; then
        pass "$label, ring perf, a bucket past its room: the step refused, then cell by cell"
    else
        fail "$label, ring perf, a bucket past its room: the step refused" "stats: $(grep refused "$TMP/err")"
    fi
    # the keyed steps above sort their tables in buckets (cuda_rows.cuh), a rank past 255 refusing the step; here
    # they count them cell by cell (count_kernel) as well
    same_bytes "$label, ring perf, counted cell by cell" "$TMP/cuda_crowd_ring_perf.in.expected" \
        env SIM_CUDA_SCAN_TILES=0 SIM_CUDA_ROWS=0 timeout 120 ./cuda "$TMP/cuda_crowd_ring_perf.in" --quiet --stats
    if grep -q "one for a cell past 255 disks" "$TMP/err"; then
        pass "$label, ring perf, counted cell by cell: the crowded cell's step refused, then 32 bits"
    else
        fail "$label, ring perf, counted cell by cell: the crowded cell's step refused" \
            "stats: $(grep refused "$TMP/err")"
    fi
    same_bytes "$label, the slow gas" "$TMP/cuda_slow_perf.expected" env SIM_CUDA_SCAN_TILES=0 \
        ./cuda "$TMP/cuda_slow_perf.in" --quiet --stats
    if grep -q " 0 steps refused" "$TMP/err" && ! grep -q "past 255" "$TMP/err"; then
        pass "$label, the slow gas: no step refused"
    else
        fail "$label, the slow gas: no step refused" "stats: $(grep refused "$TMP/err")"
    fi
else
    skip "$label" "no GPU"
fi

# --pressure is not offered by cuda: one line on stderr, nothing on stdout, non-zero exit
if [ -x ./cuda ]; then
    expect_error "cuda --pressure rejected with one line" "--pressure" ./cuda "inputs/$(ls inputs | head -1)" --pressure
else
    skip "cuda --pressure rejected" "./cuda not built"
fi

# A run the GPU cannot hold is stopped while its input is still being read (cuda_prepare): 2e9 disks
# (some 300 GB, more than any one GPU has), placed at random, with nothing on stdout and one line
# naming where N was read and the size the run needs. The placement alone would take minutes: an exit
# within the time limit is the check's second half.
label="cuda: a run larger than the GPU refused as its input is read"
if have_gpu; then
    printf '2000000000\n1000000\n1\n10\nperf\n' > "$TMP/cuda_too_big.in"
    expect_error "$label" "^cuda: $TMP/cuda_too_big.in:1: 2000000000 disks need at least [0-9.]+ GB of GPU memory" \
        timeout 60 ./cuda "$TMP/cuda_too_big.in" --quiet
    # the same header with a bad line after it: the parse fails before the context is up, and its one line
    # is all (the refusal for memory, whose check comes later, stays silent as the process exits)
    printf '2000000000\n1000000\n1\n10\nperf\n0 1 2 3\n' > "$TMP/cuda_too_big_bad.in"
    expect_error "$label, after a bad line: that line's message alone" \
        "^cuda: $TMP/cuda_too_big_bad.in:6: expected 5 fields" timeout 60 ./cuda "$TMP/cuda_too_big_bad.in" --quiet
else
    skip "$label" "no GPU"
    skip "$label, after a bad line" "no GPU"
fi
