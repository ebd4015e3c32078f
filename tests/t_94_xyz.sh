# tools/xyz: simulator outputs as extended XYZ. Bundled print and perf outputs, fresh seq runs (%.8f
# and --dump17, S = 0) checked frame by frame against the output by an independent awk script; stdin
# gives the bytes a file gives; malformed, cut or mismatched outputs, bad headers, missing files and a
# full disk are refused with one line naming the file and line; memory does not grow with the steps;
# and ASE, installed into a virtual environment under $TMP where pip can reach it, reads the frames back.
X=$TMP/xyz
mkdir -p "$X"

# ---- the frames against the output they came from --------------------------------------------------
# xyz_verify NAME INPUT OUTPUT XYZ: every frame of XYZ is the matching state of OUTPUT. The expected
# steps come from INPUT's header (step 0, steps 1..S-1 in print mode, step S with counts); each frame
# has the count line, the comment line with Lattice "L 0 0 0 L 0 0 0 2r", the Properties (plus the
# counts' columns on the last frame), Time = the step and pbc "F F F", then N lines "i x y 0 vx vy 0 r"
# whose x y vx vy (and p w) are the output's tokens, compared as strings.
xyz_verify() {
    local name=$1 in=$2 out=$3 xyz=$4 bad
    bad=$(awk -v in_file="$in" -v out_file="$out" '
        function problem(msg) { print "xyz line " FNR ": " msg; failed = 1; exit }
        BEGIN {
            base = "id:I:1:pos:R:3:velo:R:3:radius:R:1"
            counts = ":collisions:I:1:wall_collisions:I:1"
            while (k < 5 && (getline hl < in_file) > 0) {
                gsub(/\r/, "", hl)
                if (split(hl, t, " ") == 0) continue
                head[++k] = t[1]
            }
            n = head[1] + 0; L = head[2] + 0; r = head[3] + 0; S = head[4] + 0
            frames = head[5] == "print" && S > 1 ? S + 1 : 2
            frame = 0; pos = 0   # pos: 0 count line, 1 comment line, 2.. disk lines
        }
        {
            if (frame == frames) problem("more lines than " frames " frames")
            last = frame == frames - 1; step = last ? S : frame
            if (pos == 0) {
                if ($0 != n "") problem("count line \"" $0 "\", expected " n)
                pos = 1; next
            }
            if (pos == 1) {
                want = "^Lattice=\"[^ \"]+ 0 0 0 [^ \"]+ 0 0 0 [^ \"]+\" Properties=" base (last ? counts : "") \
                       " Time=" step " pbc=\"F F F\"$"
                if ($0 !~ want) problem("comment line \"" $0 "\", expected the pattern " want)
                split($0, q, "\""); split(q[2], lat, " ")
                if (lat[1] + 0 != L || lat[5] + 0 != L || lat[9] + 0 != 2 * r)
                    problem("Lattice \"" q[2] "\", expected L = " head[2] " and 2r with r = " head[3])
                pos = 2; i = 0; next
            }
            if ((getline ol < out_file) <= 0) problem("the output has no line for disk " i " of step " step)
            m = split(ol, o, " ")
            if (m != (last ? 8 : 6) || o[1] != step "" || o[2] != i "")
                problem("output line \"" ol "\" is not disk " i " of step " step)
            if (NF != (last ? 10 : 8)) problem(NF " fields, expected " (last ? 10 : 8))
            if ($1 "" != o[2] "" || $2 "" != o[3] "" || $3 "" != o[4] "" || $5 "" != o[5] "" || $6 "" != o[6] "")
                problem("disk line \"" $0 "\" does not copy the output line \"" ol "\"")
            if ($4 "" != "0" || $7 "" != "0") problem("z or vz not 0: \"" $0 "\"")
            if ($8 + 0 != r) problem("radius " $8 ", expected " r)
            if (last && ($9 "" != o[7] "" || $10 "" != o[8] "")) problem("counts \"" $9 " " $10 "\", expected \"" o[7] " " o[8] "\"")
            if (++i == n) { frame++; pos = 0 }
        }
        END {
            if (failed) exit
            if (frame != frames || pos != 0) { print "the file ends in frame " frame " (line " pos "), expected " frames " frames"; exit }
            if ((getline ol < out_file) > 0) { print "the output has more lines: \"" ol "\""; exit }
        }' "$xyz" 2>&1 | head -n 1)
    if [ -z "$bad" ]; then pass "xyz/$name"; else fail "xyz/$name" "$bad"; fi
}

# xyz_convert NAME INPUT OUTPUT [NOTE]: tools/xyz INPUT OUTPUT > $X/NAME.xyz, then xyz_verify.
xyz_convert() {
    if ! tools/xyz "$2" "$3" > "$X/$1.xyz" 2> "$X/err"; then
        fail "xyz/$1${4:+ ($4)}" "exit status $?: $(head -c 300 "$X/err")"
        return
    fi
    # an awk-free count too: one frame per printed step, N + 2 lines each
    local n steps frames
    n=$(awk 'NF { print $1; exit }' "$2")
    steps=$(($(wc -l < "$3") / n))
    frames=$(grep -c '^Lattice=' "$X/$1.xyz")
    if [ "$frames" -eq "$steps" ] && [ "$(wc -l < "$X/$1.xyz")" -eq $((steps * (n + 2))) ]; then
        pass "xyz/$1${4:+ ($4)}: $frames frames of $n + 2 lines for $steps printed steps"
    else
        fail "xyz/$1${4:+ ($4)}: frames for printed steps" \
            "$frames frames, $(wc -l < "$X/$1.xyz") lines for $steps steps of $n"
    fi
    xyz_verify "$1${4:+ ($4)}: frames equal the output" "$2" "$3" "$X/$1.xyz"
}

xyz_convert "random_300_print" inputs/random_300_print.in outputs/random_300_print.out
xyz_convert "random_1000_perf" inputs/random_1000_perf.in outputs/random_1000_perf.out
xyz_convert s_zero_print tests/hard/s_zero_print.in tests/hard/s_zero_print.out "S = 0: step 0 twice"
tools/gen 40 --fraction 0.3 --speed 0.6 --steps 25 --mode print --seed 11 > "$X/small.in"
./seq "$X/small.in" --quiet > "$X/small.out"
./seq "$X/small.in" --quiet --dump17 > "$X/small.d17"
xyz_convert small_print "$X/small.in" "$X/small.out" "fresh seq run"
xyz_convert small_dump17 "$X/small.in" "$X/small.d17" "fresh seq --dump17 run"

# ---- streaming: stdin gives the bytes a file gives --------------------------------------------------
if ./seq "$X/small.in" --quiet | tools/xyz "$X/small.in" > "$X/piped.xyz" 2> "$X/err" &&
    cmp -s "$X/piped.xyz" "$X/small_print.xyz"; then
    pass "xyz/seq | tools/xyz INPUT: the same bytes as from the file"
else
    fail "xyz/seq | tools/xyz INPUT: the same bytes as from the file" "$(head -c 200 "$X/err")"
fi
if tools/xyz inputs/random_300_print.in - < outputs/random_300_print.out > "$X/dash.xyz" 2> "$X/err" &&
    cmp -s "$X/dash.xyz" "$X/random_300_print.xyz"; then
    pass "xyz/OUTPUT - reads stdin: the same bytes as from the file"
else
    fail "xyz/OUTPUT - reads stdin: the same bytes as from the file" "$(head -c 200 "$X/err")"
fi

# ---- refusals: exit status 1 and one stderr line ------------------------------------------------------
# xyz_rejects NAME PATTERN ARGS...: tools/xyz ARGS (stdin from STDIN_FILE, else /dev/null) exits with
# status 1 and prints exactly one stderr line matching PATTERN (grep -E). Frames before the problem
# may be on stdout: a filter cannot take back what it streamed, so the status is what tells.
xyz_rejects() {
    local name=$1 pattern=$2 rc problems=""
    shift 2
    tools/xyz "$@" > "$X/out" 2> "$X/err" < "${STDIN_FILE:-/dev/null}"
    rc=$?
    [ "$rc" -eq 1 ] || problems="exit status $rc;"
    [ "$(wc -l < "$X/err")" -eq 1 ] || problems="$problems $(wc -l < "$X/err") stderr lines;"
    grep -Eq -e "$pattern" "$X/err" || problems="$problems message '$(head -c 200 "$X/err")';"
    if [ -z "$problems" ]; then pass "xyz/rejects $name"; else fail "xyz/rejects $name" "$problems"; fi
}
P_IN=inputs/random_300_print.in
P_OUT=outputs/random_300_print.out
# cut in the middle of line 1000 (its last 20 bytes gone, no newline)
head -n 1000 "$P_OUT" | head -c -20 > "$X/cut.out"
xyz_rejects "an output cut inside a line" "^xyz: $X/cut.out:1000: .*newline" "$P_IN" "$X/cut.out"
head -n 3000 "$P_OUT" > "$X/short.out"
xyz_rejects "an output cut after 10 of 21 states" "^xyz: $X/short.out:3001: .*10 of 21 states" "$P_IN" "$X/short.out"
sed 4d "$P_OUT" > "$X/gap.out"
xyz_rejects "a missing line" "^xyz: $X/gap.out:4: expected disk 3" "$P_IN" "$X/gap.out"
xyz_rejects "the output of another input (N = 300 for N = 1000)" \
    "^xyz: $P_OUT:301: expected step 0, found '1'" inputs/random_1000_perf.in "$P_OUT"
xyz_rejects "the output of another input (N = 1000 for N = 300)" \
    "^xyz: outputs/random_1000_perf.out:301: expected step 1, found '0'" "$P_IN" outputs/random_1000_perf.out
sed 's/^print/perf/' "$P_IN" > "$X/perf_mode.in"
xyz_rejects "a print output for a perf input" "^xyz: $P_OUT:301: expected 8 fields" "$X/perf_mode.in" "$P_OUT"
sed '500s/.*/garbage in the middle/' "$P_OUT" > "$X/garbage.out"
xyz_rejects "a garbage line" "^xyz: $X/garbage.out:500: expected 6 fields" "$P_IN" "$X/garbage.out"
sed '501s/ [^ ]*$/ nan/' "$P_OUT" > "$X/nan.out"
xyz_rejects "a nan" "^xyz: $X/nan.out:501: field 6 'nan' is not a finite real" "$P_IN" "$X/nan.out"
sed '502s/^\([^ ]* [^ ]* \)[^ ]*/\11e999/' "$P_OUT" > "$X/inf.out"
xyz_rejects "an overflowing real" "^xyz: $X/inf.out:502: field 3 '1e999' is not a finite real" "$P_IN" "$X/inf.out"
sed '6300s/ [0-9]*$/ -1/' "$P_OUT" > "$X/count.out"
xyz_rejects "a negative count" "^xyz: $X/count.out:6300: field 8 '-1' is not a plain integer" "$P_IN" "$X/count.out"
cat "$P_OUT" "$P_OUT" > "$X/twice.out"
xyz_rejects "an output twice over" "^xyz: $X/twice.out:6301: more lines" "$P_IN" "$X/twice.out"
STDIN_FILE=$X/garbage.out xyz_rejects "garbage on stdin" "^xyz: -:500: expected 6 fields" "$P_IN"
xyz_rejects "a missing OUTPUT" "^xyz: cannot open $X/none.out" "$P_IN" "$X/none.out"
xyz_rejects "a missing INPUT" "^xyz: cannot open $X/none.in" "$X/none.in" "$P_OUT"
printf '300\n3000\n1\n20\nprints\n' > "$X/bad_mode.in"
xyz_rejects "a bad mode in INPUT" "^xyz: $X/bad_mode.in:5: the mode must be print or perf" "$X/bad_mode.in" "$P_OUT"
printf '300\n3000\n\n2000\n20\nprint\n' > "$X/bad_r.in"
xyz_rejects "2r > L in INPUT" "^xyz: $X/bad_r.in:4: r must be" "$X/bad_r.in" "$P_OUT"
printf '300\n3000\n' > "$X/short.in"
xyz_rejects "a short INPUT header" "^xyz: $X/short.in:3: the header ends before r" "$X/short.in" "$P_OUT"
tools/xyz "$P_IN" "$P_OUT" > /dev/full 2> "$X/err"
rc=$?
if [ "$rc" -eq 1 ] && [ "$(wc -l < "$X/err")" -eq 1 ] && grep -q '^xyz: cannot write standard output' "$X/err"; then
    pass "xyz/rejects /dev/full as stdout"
else
    fail "xyz/rejects /dev/full as stdout" "exit status $rc, '$(head -c 200 "$X/err")'"
fi
# usage: --help on stdout with status 0, none or too many arguments on stderr with status 2
tools/xyz --help > "$X/out" 2> "$X/err"
rc=$?
if [ "$rc" -eq 0 ] && grep -q '^usage: tools/xyz \[--periodic\] INPUT' "$X/out" && [ ! -s "$X/err" ]; then
    pass "xyz/--help"
else
    fail "xyz/--help" "exit status $rc"
fi
bad=""
for args in "" "a b c" "--bogus $P_IN"; do
    # shellcheck disable=SC2086
    tools/xyz $args > "$X/out" 2> "$X/err" < /dev/null
    rc=$?
    { [ "$rc" -eq 2 ] && [ ! -s "$X/out" ] && grep -q '^usage: tools/xyz' "$X/err"; } || bad="$bad [$args]:$rc"
done
if [ -z "$bad" ]; then pass "xyz/bad usage: usage on stderr, status 2"; else fail "xyz/bad usage" "$bad"; fi

# ---- constant memory ------------------------------------------------------------------------------------
# 100 disks printed for 10 and for 2000 steps (about 60 kB and 12 MB of output): the peak resident
# size must not grow with the steps (1 MB of slack for the C library).
if [ -x /usr/bin/time ] && /usr/bin/time -f %M true > /dev/null 2>&1; then
    kb=""
    for s in 10 2000; do
        tools/gen 100 --fraction 0.2 --steps "$s" --mode print --seed 4 > "$X/mem_$s.in"
        ./seq "$X/mem_$s.in" --quiet > "$X/mem_$s.out"
        /usr/bin/time -o "$X/mem_$s.kb" -f %M tools/xyz "$X/mem_$s.in" "$X/mem_$s.out" > /dev/null 2> "$X/err" ||
            kb="$kb $s:exit"
        kb="$kb $(tail -n 1 "$X/mem_$s.kb")"
    done
    read -r k10 k2000 <<< "$kb"
    if [[ $k10 =~ ^[0-9]+$ && $k2000 =~ ^[0-9]+$ ]] && [ "$k2000" -le $((k10 + 1024)) ]; then
        pass "xyz/constant memory: $k10 kB for 10 steps, $k2000 kB for 2000"
    else
        fail "xyz/constant memory" "peak kB:$kb ($(wc -c < "$X/mem_2000.out") bytes of output)"
    fi
    rm -f "$X"/mem_*
else
    skip "xyz/constant memory" "no GNU /usr/bin/time"
fi

# ---- ASE reads the frames ---------------------------------------------------------------------------
# ase.io.read(..., index=':', format='extxyz') on three conversions: frame and atom counts, positions
# and velocities (to 1e-8 relative) against the output's tokens, z = vz = 0, the cell diag(L, L, 2r),
# pbc off, Time, ids, radii, and the counts on the last frame only. ASE goes into a virtual
# environment under tests/tmp (ignored by git), made once and reused; no network or no venv is a SKIP.
cat > "$X/ase_check.py" <<'PY'
import sys
import numpy as np
from ase.io import read

def header(path):
    tokens = []
    with open(path) as f:
        for line in f:
            if line.split():
                tokens.append(line.split()[0])
            if len(tokens) == 5:
                break
    return int(tokens[0]), float(tokens[1]), float(tokens[2]), int(tokens[3]), tokens[4]

def check(inp, out, xyz):
    n, L, r, S, mode = header(inp)
    rows = [line.split() for line in open(out)]
    states = [rows[k:k + n] for k in range(0, len(rows), n)]
    frames = read(xyz, index=':', format='extxyz')
    assert len(frames) == len(states), f"{len(frames)} frames, {len(states)} states"
    want_frames = S + 1 if mode == 'print' and S > 1 else 2
    assert len(frames) == want_frames, f"{len(frames)} frames, expected {want_frames}"
    cell = np.diag([L, L, 2 * r])
    for k, (atoms, state) in enumerate(zip(frames, states)):
        last = k == len(frames) - 1
        assert len(atoms) == n, f"frame {k}: {len(atoms)} atoms"
        step = int(state[0][0])
        assert atoms.info.get('Time') == step, f"frame {k}: Time {atoms.info.get('Time')}, step {step}"
        assert np.allclose(atoms.cell.array, cell, rtol=1e-15, atol=0), \
            f"frame {k}: cell {atoms.cell.array.tolist()}, expected diag({L}, {L}, {2 * r})"
        assert not any(atoms.pbc), f"frame {k}: pbc {atoms.pbc}"
        xy = np.array([[float(t[2]), float(t[3])] for t in state])
        v = np.array([[float(t[4]), float(t[5])] for t in state])
        pos, velo = atoms.positions, atoms.arrays['velo']
        for name, got, ref in (('positions', pos, xy), ('velocities', velo, v)):
            err = np.abs(got[:, :2] - ref)
            assert np.all(err <= 1e-8 * np.abs(ref)), f"frame {k}: {name} differ by up to {err.max()}"
            assert np.all(got[:, 2] == 0), f"frame {k}: {name} z not 0"
        assert np.array_equal(atoms.arrays['id'], np.arange(n)), f"frame {k}: ids"
        assert np.all(atoms.arrays['radius'] == r), f"frame {k}: radii"
        has = 'collisions' in atoms.arrays and 'wall_collisions' in atoms.arrays
        assert has == last, f"frame {k}: counts present: {has}"
        if last:
            p = np.array([int(t[6]) for t in state])
            w = np.array([int(t[7]) for t in state])
            assert np.array_equal(atoms.arrays['collisions'], p), "collision counts"
            assert np.array_equal(atoms.arrays['wall_collisions'], w), "wall collision counts"
    return len(frames)

try:
    print(check(*sys.argv[1:4]), 'frames')
except AssertionError as e:
    sys.exit(' '.join(str(e).split()))
PY
# (the environment lives beside the test files' own folders, which every run empties; the quick suite
# uses it where an earlier run made it, and leaves the 20 s install to make test-all)
VENV=tests/tmp/ase_venv
ase_reason=""
if ! python3 -c 'import venv, ensurepip' > /dev/null 2>&1; then
    ase_reason="python3 has no venv (or ensurepip) module"
elif ! all_suite && ! "$VENV/bin/python" -c 'import ase' > /dev/null 2>&1; then
    ase_reason="ASE not installed yet (make test-all installs it into $VENV)"
elif ! "$VENV/bin/python" -c 'import ase' > /dev/null 2>&1; then
    rm -rf "$VENV"
    if ! timeout 120 python3 -m venv "$VENV" > "$X/venv.log" 2>&1; then
        ase_reason="python3 -m venv failed: $(tail -n 1 "$X/venv.log")"
    elif ! timeout 300 "$VENV/bin/pip" install --quiet --disable-pip-version-check --timeout 15 --retries 1 \
        ase > "$X/pip.log" 2>&1; then
        ase_reason="pip install ase failed (no network?): $(grep -v '^ *$' "$X/pip.log" | tail -n 1 | head -c 200)"
    elif ! "$VENV/bin/python" -c 'import ase' > /dev/null 2>&1; then
        ase_reason="ase installed but not importable"
    fi
fi
for name in random_300_print random_1000_perf small_dump17; do
    case $name in
        random_*) in=inputs/$name.in out=outputs/$name.out ;;
        *) in=$X/small.in out=$X/small.d17 ;;
    esac
    if [ -n "$ase_reason" ]; then
        skip "xyz/ASE reads $name" "$ase_reason"
    elif got=$("$VENV/bin/python" "$X/ase_check.py" "$in" "$out" "$X/$name.xyz" 2>&1); then
        pass "xyz/ASE reads $name: $got, atoms, positions, velocities, cell, pbc, counts"
    else
        fail "xyz/ASE reads $name" "$(tail -n 1 <<< "$got" | head -c 300)"
    fi
done
