# mpi --checkpoint / --resume (checkpoint.c written and read in parts by mpi_io.c):
# - mpi at 1, 2 and 3 ranks (1 to 5 in the whole suite) writes seq's checkpoint file byte for byte, in
#   print and perf mode, walled with --substeps 2 --pressure and periodic with --pressure (the
#   virial's sums in the header), and prints the plain run's bytes;
# - resumed across backends: seq's checkpoint by mpi at 2 and 3 ranks, mpi's (3 ranks) by seq, omp
#   and mpi at 2 ranks, each printing seq's resumed stdout and stderr (but for the program's name), in
#   print mode and periodic perf with --pressure (the whole suite: the other two scenes too);
# - damaged (the whole suite: cut and other-version too) checkpoints refused by mpi with seq's line;
# - kill trials at 2 and 3 ranks (ck_trial, tests/lib.sh): every process of the job killed with
#   SIGKILL, resumed by mpi at another rank count. They write through --output FILE: mpirun passes a
#   rank's stdout on itself, and a killed mpirun loses what it had not passed on yet.
# CK_SEED=N repeats the random moments of an earlier run (its seed is in the first line).
C=$TMP/mck
mkdir -p "$C"
if ! have_mpi; then
    skip "mpi checkpoints" "no mpirun or no ./mpi"
else
    mpi_env
    CK_SEED=${CK_SEED:-$(( $(date +%s) % 32768 ))}
    RANDOM=$CK_SEED
    CK_KILLS=0
    ./tools/gen 500 --fraction 0.3 --steps 40 --mode print --seed 7 > "$C/print.in"
    ./tools/gen 500 --fraction 0.3 --steps 40 --seed 5 > "$C/perf.in"
    ./tools/gen 500 --periodic --fraction 0.3 --steps 40 --mode print --seed 7 > "$C/pprint.in"
    ./tools/gen 300 --periodic --assignment --L 300 --steps 40 --seed 8 > "$C/pperf.in"
    ranks=$(if all_suite; then echo 1 2 3 4 5; else echo 1 2 3; fi)

    # ---- mpi writes seq's checkpoint file ----
    # ck_same NAME "RANKS" ARGS...: seq's checkpoint (every 13 steps) and stdout, then mpi's at each rank count
    ck_same() {
        local name=$1 counts=$2 p bad=""
        shift 2
        rm -f "$C/seq.ck"
        ./seq "$@" --quiet --checkpoint "$C/seq.ck" --checkpoint-every 13 > "$C/seq.out" 2> /dev/null
        for p in $counts; do
            rm -f "$C/mpi.ck"
            if ! run_mpi "$p" 1 "$@" --quiet --checkpoint "$C/mpi.ck" --checkpoint-every 13 > "$C/out" 2> "$C/err"; then
                bad="$bad $p:exit($(head -c 150 "$C/err"))"
            elif ! cmp -s "$C/out" "$C/seq.out"; then
                bad="$bad $p:stdout differs"
            elif ! cmp -s "$C/mpi.ck" "$C/seq.ck" || [ -e "$C/mpi.ck.tmp" ]; then
                bad="$bad $p:checkpoint differs($(cmp "$C/mpi.ck" "$C/seq.ck" 2>&1 | head -1))"
            fi
        done
        if [ -z "$bad" ]; then pass "mpi checkpoint $name: seq's file at $counts ranks"; else fail "mpi checkpoint $name" "$bad"; fi
    }
    ck_same "print" "$ranks" "$C/print.in"
    ck_same "perf --substeps 2 --pressure" "$ranks" "$C/perf.in" --substeps 2 --pressure
    ck_same "periodic print --pressure" "$ranks" "$C/pprint.in" --periodic --pressure
    ck_same "periodic perf --substeps 2 --pressure" "$(if all_suite; then echo "$ranks"; else echo 3; fi)" \
        "$C/pperf.in" --periodic --substeps 2 --pressure

    # ---- resumed across backends: seq's resumed stdout and stderr ----
    # ck_resume NAME FILE PROG...: PROG --resume FILE prints what seq --resume FILE prints (stderr: the
    # timing line aside, the program's name seq)
    ck_resume() {
        local name=$1 file=$2
        shift 2
        if [ ! -e "$file.ref" ]; then
            ./seq --resume "$file" > "$file.ref" 2> "$C/r.ref.err"
            grep -v ' particles, .* steps, ' "$C/r.ref.err" > "$file.ref.err"
        fi
        if ! "$@" --resume "$file" > "$C/r.out" 2> "$C/r.err"; then
            fail "$name" "exit: $(head -c 200 "$C/r.err")"
        elif ! cmp -s "$C/r.out" "$file.ref"; then
            fail "$name" "stdout differs from seq's ($(cmp "$C/r.out" "$file.ref" 2>&1 | head -1))"
        elif ! grep -v ' particles, .* steps, ' "$C/r.err" | sed 's/^[a-z_0-9]*: /seq: /' | cmp -s - "$file.ref.err"; then
            fail "$name" "stderr differs from seq's: $(head -c 300 "$C/r.err")"
        else
            pass "$name"
        fi
    }
    scenes="print pperf"
    all_suite && scenes="print perf pprint pperf"
    for scene in $scenes; do
        case $scene in
            print) args=() ;;
            perf) args=(--substeps 2 --pressure) ;;
            pprint) args=(--periodic --pressure) ;;
            pperf) args=(--periodic --substeps 2 --pressure) ;;
        esac
        ./seq "$C/$scene.in" "${args[@]}" --quiet --checkpoint "$C/$scene.seq.ck" --checkpoint-every 13 > /dev/null 2>&1
        run_mpi 3 1 "$C/$scene.in" "${args[@]}" --quiet --checkpoint "$C/$scene.mpi.ck" --checkpoint-every 9 \
            > /dev/null 2>&1
        for p in 2 3; do
            ck_resume "mpi resume $scene: seq's checkpoint at $p ranks" "$C/$scene.seq.ck" run_mpi "$p" 1
        done
        ck_resume "mpi resume $scene: mpi's checkpoint (3 ranks) by seq" "$C/$scene.mpi.ck" ./seq
        ck_resume "mpi resume $scene: mpi's checkpoint (3 ranks) by omp 2 threads" "$C/$scene.mpi.ck" ./omp --threads 2
        ck_resume "mpi resume $scene: mpi's checkpoint (3 ranks) by mpi at 2 ranks" "$C/$scene.mpi.ck" run_mpi 2 1
    done
    # a resumed run's own checkpoints: seq's bytes too
    cp "$C/pperf.mpi.ck" "$C/again.seq.ck"
    cp "$C/pperf.mpi.ck" "$C/again.mpi.ck"
    ./seq --resume "$C/again.seq.ck" --quiet --checkpoint "$C/again.seq.ck" --checkpoint-every 1 > /dev/null 2>&1
    run_mpi 3 1 --resume "$C/again.mpi.ck" --quiet --checkpoint "$C/again.mpi.ck" --checkpoint-every 1 > /dev/null 2>&1
    if ! cmp -s "$C/pperf.mpi.ck" "$C/again.seq.ck" && cmp -s "$C/again.seq.ck" "$C/again.mpi.ck"; then
        pass "mpi checkpoint: a resumed periodic --pressure run at 3 ranks writes seq's later checkpoint"
    else
        fail "mpi checkpoint: a resumed run's checkpoint" "differs from seq's (or was not written)"
    fi

    # ---- refused checkpoints: seq's line, one on stderr, nothing on stdout ----
    good=$C/print.seq.ck
    size=$(wc -c < "$good")
    flip() { # FILE OFFSET: inverts the bits of one byte
        local b
        b=$(od -An -tu1 -j "$2" -N1 "$1" | tr -d ' ')
        printf "\\$(printf %o $((255 - b)))" | dd of="$1" bs=1 seek="$2" conv=notrunc status=none
    }
    head -c $((size - 1)) "$good" > "$C/cut.ck"
    cp "$good" "$C/flip.ck" && flip "$C/flip.ck" $((size / 2))
    cp "$good" "$C/version.ck" && flip "$C/version.ck" 8
    # (each refusal takes mpirun a second to end the job: the quick suite tries the damaged byte only)
    for bad in $(if all_suite; then echo cut flip version; else echo flip; fi); do
        ./seq --resume "$C/$bad.ck" > /dev/null 2> "$C/seq.err"
        line=$(sed 's/^seq: //; s/[][\.*^$(){}?+|]/\\&/g' "$C/seq.err")
        expect_mpi_error "mpi refuses a $bad checkpoint with seq's line" "^mpi: $line\$" --resume "$C/$bad.ck"
    done

    # ---- kill trials: every step (kills inside the checkpoints' writing) and every few ----
    ./tools/gen 150 --speed 0.5 --steps 1500 --mode print --seed 3 > "$C/kill.in"
    ./tools/gen 150 --periodic --speed 0.5 --steps 1500 --mode print --seed 9 > "$C/pkill.in"
    ./seq "$C/kill.in" --quiet > "$C/kill.ref"
    ./seq "$C/pkill.in" --periodic --quiet > "$C/pkill.ref"
    mpi="${MPIRUN[*]} --oversubscribe -np"
    min_kills=2
    all_suite && min_kills=6
    ck_trial "kill: mpi 2 ranks print every step, resumed by mpi 3 ranks" "$C/kill.ref" 150 print 1 0.5 \
        "$mpi 2 ./mpi $C/kill.in --output @OUT@" "$mpi 3 ./mpi --output @OUT@"
    ck_trial "kill: mpi 3 ranks print, resumed by mpi 2 ranks" "$C/kill.ref" 150 print 7 0.25 \
        "$mpi 3 ./mpi $C/kill.in --output @OUT@" "$mpi 2 ./mpi --output @OUT@"
    all_suite && ck_trial "kill: mpi 3 ranks print every step, twice, resumed by mpi 2 then 3 ranks" "$C/kill.ref" \
        150 print 1 0.4 "$mpi 3 ./mpi $C/kill.in --output @OUT@" "$mpi 2 ./mpi --output @OUT@" \
        "$mpi 3 ./mpi --output @OUT@"
    all_suite && ck_trial "kill: mpi 2 ranks --periodic print every step, resumed by mpi 3 ranks" "$C/pkill.ref" 150 \
        print 1 0.5 "$mpi 2 ./mpi $C/pkill.in --periodic --output @OUT@" "$mpi 3 ./mpi --output @OUT@"
    all_suite && ck_trial "kill: mpi 3 ranks print, resumed by seq" "$C/kill.ref" 150 print 3 0.3 \
        "$mpi 3 ./mpi $C/kill.in --output @OUT@" "./seq"
    if [ "$CK_KILLS" -ge "$min_kills" ]; then
        pass "kill: $CK_KILLS mpi jobs killed with SIGKILL and resumed (seed $CK_SEED)"
    else
        fail "kill: mpi trials" "only $CK_KILLS jobs were killed (at least $min_kills wanted; seed $CK_SEED)"
    fi
fi
