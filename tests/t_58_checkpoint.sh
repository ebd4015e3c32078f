# --checkpoint / --resume: runs killed with SIGKILL at random moments and resumed.
# - A checkpointing run prints the same bytes as one without; the checkpoint of a step is the same file
#   whichever backend and thread count wrote it (seq, omp at 1, 2, 3 and 7 threads, cuda on a GPU).
# - Kill trials: a run is started with --checkpoint, killed with kill -9 at a random moment after its
#   first checkpoint (some runs checkpoint every step, so that kills land inside a checkpoint's
#   writing), and resumed, some by another backend or thread count, some killed again while resumed.
#   The interrupted stdout cut after the checkpoint's step (perf: after step 0), followed by the resumed
#   runs' stdout, must be the uninterrupted run's bytes. Runs of the periodic box (--periodic) among
#   them, taking the option from the checkpoint.
# - Damaged, cut, extended, other-version and other-precision checkpoints, and the option conflicts,
#   are refused with one stderr line, nothing on stdout and a non-zero exit.
# CK_SEED=N repeats the random moments of an earlier run (its seed is in the first line).
C=$TMP/ck
mkdir -p "$C"
CK_SEED=${CK_SEED:-$(( $(date +%s) % 32768 ))}
RANDOM=$CK_SEED
CK_KILLS=0

./tools/gen 150 --speed 0.5 --steps 1500 --mode print --seed 3 > "$C/print.in"
./tools/gen 400 --assignment --L 400 --steps 500 --seed 4 > "$C/fast.in"
./tools/gen 3000 --fraction 0.3 --steps 1000 --seed 5 > "$C/gas.in"
./tools/gen 200 --assignment --L 300 --steps 250 --mode print --seed 6 > "$C/exact.in"
./tools/gen 500 --fraction 0.3 --steps 40 --mode print --seed 7 > "$C/small.in"
# the periodic box (SPEC.md 7): fast paths over the edges, and a small print-mode gas
./tools/gen 300 --periodic --assignment --L 300 --steps 400 --seed 8 > "$C/periodic.in"
./tools/gen 150 --periodic --speed 0.5 --steps 1500 --mode print --seed 9 > "$C/pprint.in"
./tools/gen 500 --periodic --fraction 0.3 --steps 40 --mode print --seed 7 > "$C/psmall.in"

# ---- a checkpointing run prints what a plain run prints; its checkpoints agree across backends ----
./seq "$C/small.in" --quiet > "$C/small.ref"
./seq "$C/small.in" --quiet --checkpoint "$C/seq.ck" --checkpoint-every 13 > "$C/out"
if cmp -s "$C/out" "$C/small.ref" && [ -s "$C/seq.ck" ] && [ ! -e "$C/seq.ck.tmp" ]; then
    pass "checkpoint: seq --checkpoint prints the plain run's bytes, leaves no .tmp (seed $CK_SEED)"
else
    fail "checkpoint: seq --checkpoint" "output or checkpoint file wrong"
fi
ck_same() { # NAME COMMAND...: the checkpoint of step 39 (every 13) must be seq's file, and stdout the same
    local name=$1
    shift
    rm -f "$C/other.ck"
    if ! "$@" "$C/small.in" --quiet --checkpoint "$C/other.ck" --checkpoint-every 13 > "$C/out" 2> "$C/err"; then
        fail "$name" "exit: $(head -c 200 "$C/err")"
    elif ! cmp -s "$C/out" "$C/small.ref"; then
        fail "$name" "stdout differs from the plain run's"
    elif ! cmp -s "$C/other.ck" "$C/seq.ck"; then
        fail "$name" "its checkpoint differs from seq's ($(cmp "$C/other.ck" "$C/seq.ck" 2>&1 | head -1))"
    else
        pass "$name"
    fi
}
for t in 1 2 3 7; do ck_same "checkpoint: omp $t threads writes seq's checkpoint file" ./omp --threads "$t"; done
if have_gpu; then
    ck_same "checkpoint: cuda writes seq's checkpoint file" ./cuda
    # steps refused (their events overflow a list of 2) and run again around the checkpoints
    ck_same "checkpoint: cuda with refused steps writes seq's checkpoint file" env SIM_CUDA_EVENTS=2 ./cuda
    ck_same "checkpoint: cuda with plans of one slice and of several writes seq's checkpoint file" \
        env SIM_CUDA_PLAN_SPEED=0,1 ./cuda
else
    skip "checkpoint: cuda writes seq's checkpoint file" "no GPU"
fi

# ---- a finished run's last checkpoint, resumed: the tail of its stdout, and the same stderr lines ----
# (print mode, 40 steps, checkpoints every 13: the file holds step 39; the resumed run prints the final
# state only, with what the options of the checkpoint ask: %.17g, the pressure over the whole run)
ck_tail() { # NAME PROGRAM [OPTIONS]: on small.in (with CK_IN=FILE: FILE, of 500 disks too)
    local name=$1 prog=$2 in=${CK_IN:-$C/small.in}
    shift 2
    rm -f "$C/tail.ck"
    ./$prog "$in" --quiet "$@" > "$C/tail.ref" 2> "$C/tail.ref.err"
    ./$prog "$in" --quiet "$@" --checkpoint "$C/tail.ck" --checkpoint-every 13 > /dev/null 2>&1
    if ! ./$prog --resume "$C/tail.ck" --quiet > "$C/tail.out" 2> "$C/tail.err"; then
        fail "$name" "exit: $(head -c 200 "$C/tail.err")"
    elif ! tail -n 500 "$C/tail.ref" | cmp -s - "$C/tail.out"; then
        fail "$name" "the resumed stdout is not the last step of the plain run's"
    elif ! cmp -s "$C/tail.err" "$C/tail.ref.err"; then
        fail "$name" "stderr differs: $(head -c 200 "$C/tail.err")"
    else
        pass "$name"
    fi
}
ck_tail "resume: --dump17 comes from the checkpoint" seq --dump17
ck_tail "resume: --pressure comes from the checkpoint, the pressure line over the whole run" omp --pressure
ck_tail "resume: --substeps 4 --pressure" omp --substeps 4 --pressure --threads 3
ck_tail "resume: --exact --pressure" seq --exact --pressure
ck_tail "resume: float, --pressure" omp_f32 --pressure --threads 2
CK_IN=$C/psmall.in ck_tail "resume: --periodic --pressure (the virial's blocks come from the checkpoint)" omp \
    --periodic --pressure --threads 3
CK_IN=$C/psmall.in ck_tail "resume: --periodic --exact --pressure" seq --periodic --exact --pressure

# ---- kill trials (ck_trial: tests/lib.sh) ----
./seq "$C/print.in" --quiet > "$C/print.ref"
./omp "$C/fast.in" --quiet > "$C/fast.ref"
./omp "$C/gas.in" --quiet > "$C/gas.ref"
./omp "$C/gas.in" --quiet --substeps 2 --pressure > "$C/gas_sub.ref" 2> /dev/null
./seq "$C/exact.in" --quiet --exact > "$C/exact.ref"
./seq_f32 "$C/fast.in" --quiet > "$C/fast_f32.ref"
./omp "$C/periodic.in" --periodic --quiet --substeps 2 --pressure > "$C/periodic.ref" 2> /dev/null
./seq "$C/pprint.in" --periodic --quiet > "$C/pprint.ref"

P=$C/print.in F=$C/fast.in G=$C/gas.in X=$C/exact.in
# the quick suite runs seven of the trials (print, perf, every step, twice, --exact, float, periodic), at
# least 8 kills
min_kills=8
all_suite && min_kills=23
all_suite && ck_trial "kill: seq print, resumed by seq" "$C/print.ref" 150 print 50 0.12 "./seq $P" "./seq"
ck_trial "kill: seq print, resumed by omp 3 threads" "$C/print.ref" 150 print 7 0.12 "./seq $P" "./omp --threads 3"
all_suite && ck_trial "kill: omp 3 threads print every step, resumed by seq" "$C/print.ref" 150 print 1 0.8 \
    "./omp $P --threads 3" "./seq"
ck_trial "kill: omp 2 threads print, twice, resumed by omp 7 then 1 thread" "$C/print.ref" 150 print 3 0.25 \
    "./omp $P --threads 2" "./omp --threads 7" "./omp --threads 1"
all_suite && ck_trial "kill: seq perf, resumed by seq" "$C/fast.ref" 400 perf 10 0.25 "./seq $F" "./seq"
ck_trial "kill: seq perf, resumed by omp 2 threads" "$C/fast.ref" 400 perf 25 0.25 "./seq $F" "./omp --threads 2"
all_suite && ck_trial "kill: seq perf, twice, resumed by seq then omp 7 threads" "$C/fast.ref" 400 perf 5 0.15 \
    "./seq $F" "./seq" "./omp --threads 7"
all_suite && ck_trial "kill: omp 1 thread perf every step, resumed by omp 2 threads" "$C/gas.ref" 3000 perf 1 0.6 \
    "./omp $G --threads 1" "./omp --threads 2"
all_suite && ck_trial "kill: omp 2 threads perf, resumed by omp 3 threads" "$C/gas.ref" 3000 perf 100 0.12 \
    "./omp $G --threads 2" "./omp --threads 3"
ck_trial "kill: omp 7 threads perf every step, resumed by omp 7 threads" "$C/gas.ref" 3000 perf 1 0.8 \
    "./omp $G --threads 7" "./omp --threads 7"
all_suite && ck_trial "kill: omp 3 threads perf, twice, resumed by omp 2 then 1 thread" "$C/gas.ref" 3000 perf 40 0.08 \
    "./omp $G --threads 3" "./omp --threads 2" "./omp --threads 1"
all_suite && ck_trial "kill: omp --substeps 2 --pressure, resumed by omp 3 threads" "$C/gas_sub.ref" 3000 perf 30 0.2 \
    "./omp $G --substeps 2 --pressure --threads 2" "./omp --threads 3"
all_suite && ck_trial "kill: omp --substeps 2 --pressure, twice, resumed by omp 7 then 1 thread" "$C/gas_sub.ref" 3000 \
    perf 20 0.12 "./omp $G --substeps 2 --pressure --threads 7" "./omp --threads 7" "./omp --threads 1"
ck_trial "kill: seq --exact print, resumed by omp 2 threads" "$C/exact.ref" 200 print 5 0.12 \
    "./seq $X --exact" "./omp --threads 2"
all_suite && ck_trial "kill: omp --exact print every step, resumed by seq" "$C/exact.ref" 200 print 1 0.5 \
    "./omp $X --exact --threads 3" "./seq"
all_suite && ck_trial "kill: omp --exact print, twice, resumed by omp 1 thread then 7" "$C/exact.ref" 200 print 4 0.1 \
    "./omp $X --exact --threads 2" "./omp --threads 1" "./omp --threads 7"
all_suite && ck_trial "kill: seq_f32 perf, resumed by omp_f32 3 threads" "$C/fast_f32.ref" 400 perf 10 0.25 \
    "./seq_f32 $F" "./omp_f32 --threads 3"
ck_trial "kill: omp_f32 2 threads perf every step, resumed by seq_f32" "$C/fast_f32.ref" 400 perf 1 0.4 \
    "./omp_f32 $F --threads 2" "./seq_f32"
ck_trial "kill: seq --periodic print, resumed by omp 3 threads" "$C/pprint.ref" 150 print 7 0.12 \
    "./seq $C/pprint.in --periodic" "./omp --threads 3"
all_suite && ck_trial "kill: omp --periodic --substeps 2 --pressure perf, twice, resumed by seq then omp 7 threads" \
    "$C/periodic.ref" 300 perf 10 0.15 "./omp $C/periodic.in --periodic --substeps 2 --pressure --threads 2" "./seq" \
    "./omp --threads 7"
all_suite && ck_trial "kill: omp --periodic print every step, resumed by omp 2 threads" "$C/pprint.ref" 150 print 1 \
    0.6 "./omp $C/pprint.in --periodic --threads 3" "./omp --threads 2"
if have_gpu; then
    ck_trial "kill: cuda print, resumed by cuda" "$C/print.ref" 150 print 20 0.5 "./cuda $P" "./cuda"
    ck_trial "kill: cuda print every step, resumed by omp 3 threads" "$C/print.ref" 150 print 1 1 \
        "./cuda $P" "./omp --threads 3"
    ck_trial "kill: omp 7 threads print, resumed by cuda" "$C/print.ref" 150 print 9 0.2 \
        "./omp $P --threads 7" "./cuda"
    ck_trial "kill: cuda perf every step, twice, resumed by cuda then omp 3 threads" "$C/gas.ref" 3000 perf 1 0.5 \
        "./cuda $G" "./cuda" "./omp --threads 3"
else
    skip "kill: cuda trials (4)" "no GPU"
fi
if [ "$CK_KILLS" -ge "$min_kills" ]; then
    pass "kill: $CK_KILLS runs killed with SIGKILL and resumed"
else
    fail "kill: trials" "only $CK_KILLS runs were killed (at least $min_kills wanted)"
fi

# ---- refused checkpoints: one stderr line, nothing on stdout, non-zero exit ----
cp "$C/seq.ck" "$C/good.ck"
size=$(wc -c < "$C/good.ck")
# flip FILE OFFSET: inverts the bits of one byte
flip() {
    local b
    b=$(od -An -tu1 -j "$2" -N1 "$1" | tr -d ' ')
    printf "\\$(printf %o $((255 - b)))" | dd of="$1" bs=1 seek="$2" conv=notrunc status=none
}
head -c $((size - 1)) "$C/good.ck" > "$C/cut.ck"
{ cat "$C/good.ck"; printf 'x'; } > "$C/long.ck"
cp "$C/good.ck" "$C/flip.ck" && flip "$C/flip.ck" $((size / 2))
cp "$C/good.ck" "$C/hash.ck" && flip "$C/hash.ck" $((size - 3))
cp "$C/good.ck" "$C/version.ck" && flip "$C/version.ck" 8
cp "$C/good.ck" "$C/step.ck" && flip "$C/step.ck" 32
: > "$C/empty.ck"
./seq_f32 "$C/small.in" --quiet --checkpoint "$C/f32.ck" --checkpoint-every 13 > /dev/null
for prog in $(backend_list); do
    expect_error "refuse $prog: cut checkpoint" "cut short or extended" ./$prog --resume "$C/cut.ck"
    expect_error "refuse $prog: extended checkpoint" "cut short or extended" ./$prog --resume "$C/long.ck"
    expect_error "refuse $prog: a byte of the state changed" "checksum" ./$prog --resume "$C/flip.ck"
    expect_error "refuse $prog: the checksum changed" "checksum" ./$prog --resume "$C/hash.ck"
    expect_error "refuse $prog: another format version" "format 253.*reads formats 1 and 2" ./$prog --resume "$C/version.ck"
    expect_error "refuse $prog: impossible step" "impossible values" ./$prog --resume "$C/step.ck"
    expect_error "refuse $prog: single-precision checkpoint" "single precision.*computes in double" \
        ./$prog --resume "$C/f32.ck"
    expect_error "refuse $prog: an input file" "not a checkpoint" ./$prog --resume "$C/small.in"
    expect_error "refuse $prog: empty file" "not a checkpoint" ./$prog --resume "$C/empty.ck"
    expect_error "refuse $prog: a directory" "not a checkpoint" ./$prog --resume "$C"
    expect_error "refuse $prog: missing file" "cannot open the checkpoint" ./$prog --resume "$C/none.ck"
    expect_error "refuse $prog: resume with an input" "reads no input file" ./$prog --resume "$C/good.ck" "$C/small.in"
    expect_error "refuse $prog: resume with --substeps" "from the checkpoint" ./$prog --resume "$C/good.ck" --substeps 2
    expect_error "refuse $prog: resume with --seed" "from the checkpoint" ./$prog --resume "$C/good.ck" --seed 3
    expect_error "refuse $prog: --checkpoint-every alone" "needs --checkpoint" ./$prog "$C/small.in" --checkpoint-every 5
    expect_error "refuse $prog: --checkpoint-every 0" "checkpoint-every" ./$prog "$C/small.in" --checkpoint "$C/x.ck" \
        --checkpoint-every 0
    expect_error "refuse $prog: --checkpoint without a file" "needs a file name" ./$prog "$C/small.in" --checkpoint
    expect_error "refuse $prog: --checkpoint in a missing directory" "cannot write" ./$prog "$C/small.in" \
        --checkpoint "$C/none/x.ck"
    expect_error "refuse $prog: --checkpoint onto a directory" "not a regular file" ./$prog "$C/small.in" --checkpoint "$C"
done
expect_error "refuse seq_f32: double-precision checkpoint" "double precision.*computes in single" \
    ./seq_f32 --resume "$C/good.ck"
if have_gpu; then
    ./seq "$C/small.in" --quiet --pressure --checkpoint "$C/pressure.ck" --checkpoint-every 13 > /dev/null 2>&1
    ./seq "$C/small.in" --quiet --exact --checkpoint "$C/exact.ck" --checkpoint-every 13 > /dev/null
    expect_error "refuse cuda: a --pressure checkpoint" "does not support" ./cuda --resume "$C/pressure.ck"
    expect_error "refuse cuda: an --exact checkpoint" "does not support" ./cuda --resume "$C/exact.ck"
else
    skip "refuse cuda: --pressure and --exact checkpoints" "no GPU"
fi

# A FILE.tmp that cannot be written refuses the run before any output and leaves FILE as it was.
cp "$C/good.ck" "$C/keep.ck"
mkdir -p "$C/keep.ck.tmp"
expect_error "refuse seq: --checkpoint FILE whose FILE.tmp cannot be written" "cannot write" \
    ./seq "$C/small.in" --checkpoint "$C/keep.ck"
if cmp -s "$C/keep.ck" "$C/good.ck"; then pass "checkpoint: the refused run left FILE as it was"; else
    fail "checkpoint: the refused run changed FILE"; fi
rmdir "$C/keep.ck.tmp"
