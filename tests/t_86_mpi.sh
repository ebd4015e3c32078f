# mpi (mpi.c, mpi_io.c): the same bytes as seq for 1 to 8 ranks, oversubscribed on this machine:
# - the bundled inputs at 2 and 3 ranks (four of them at 8), the worked examples at 1 and 4, the hard
#   cases at 3;
# - the omp tests' generated scenes (tests/omp_scenes.txt) at 1 to 8 ranks and 1, 2, 3 and 7 threads
#   per rank, each scene at its own pair of combinations;
# - random placement (--seed), standard input, --dump17, --substeps 2, --pressure (the pressure line
#   too), --stats, --check;
# - the strips' cuts: by count (a gas crowded in one corner shared out), moved every step (--balance);
#   neighbourhoods wider than the adjacent strips; a speed grown by sqrt(2) in a step, whose next
#   step's pair across the cut only the grown reach finds;
# - the input read in byte ranges by every rank: files whose lines fall on the ranges' edges, blank
#   lines, CRLF;
# - --output FILE: the same bytes in FILE, written by every rank at its offset;
# - bad input (on the lines of any rank, duplicate or missing indices, too many lines) refused with
#   seq's one stderr line, nothing on stdout and mpirun's exit status non-zero. mpirun -q (Open MPI 4)
#   keeps mpirun's own notice of the failed job off stderr; an mpirun without -q (Open MPI 5) adds
#   it, and there only the program's lines ("mpi: ...") are counted.
# SKIP where mpirun or ./mpi is missing (.ci/run installs OpenMPI).
M=$TMP/mpi
mkdir -p "$M"
if ! have_mpi; then
    skip "mpi" "no mpirun or no ./mpi (apt-get install openmpi-bin libopenmpi-dev, then make)"
else
    mpi_env
    pick() { if all_suite; then echo "$1"; else echo "$2"; fi; } # the whole suite's, or the quick one's
    ranks() { # NAME EXPECTED "P[xT]..." ARGS...: mpi at each rank (x thread) count prints EXPECTED's bytes
        local name=$1 expected=$2 counts=$3 c p t bad=""
        shift 3
        for c in $counts; do
            p=${c%x*} t=1
            [ "$c" != "$p" ] && t=${c#*x}
            if ! mpi_stdin "${STDIN_FILE:-/dev/null}" run_mpi "$p" "$t" "$@" --quiet > "$M/out" 2> "$M/err"; then
                bad="$bad $c:exit($(head -c 150 "$M/err"))"
            elif ! cmp -s "$M/out" "$expected"; then
                bad="$bad $c:differs"
            fi
        done
        if [ -z "$bad" ]; then pass "mpi $name: seq's bytes at $counts ranks(xthreads)"; else fail "mpi $name" "$bad"; fi
    }
    # the quick suite: up to 3 ranks, the small bundled inputs (some hundred steps of mpirun's
    # exchanges take seconds when the ranks share 2 cores), fewer scenes and combinations
    for f in inputs/*.in; do
        b=$(basename "$f" .in)
        counts="2 3x2"
        case $b in random_1000_perf | dense_gas | overlapping_print | course_testcase2) counts="2 3x2 8" ;; esac
        if ! all_suite; then
            case $b in dense_gas) counts="2 3x2" ;; huge_box | overlapping_print) counts="3x2" ;; *) continue ;; esac
        fi
        ranks "inputs/$b" "outputs/$b.out" "$counts" "$f"
    done
    # the periodic box (SPEC.md 7): the bundled scenes with --periodic, the strips wrapping (t_78 has
    # the rest of mpi's periodic checks)
    for f in inputs/periodic/*.in; do
        b=$(basename "$f" .in)
        counts=$(pick "1 2 3x2 4 8" "")
        all_suite || case $b in edges_print) counts="3x2" ;; fast_600_perf) counts="2" ;; *) continue ;; esac
        ranks "periodic/$b" "outputs/periodic/$b.out" "$counts" "$f" --periodic
    done
    # (the quick suite: every fourth case and every sixth hard case)
    k=0
    for f in tests/cases/*.in; do
        k=$((k + 1))
        all_suite || [ $((k % 4)) = 1 ] || continue
        ranks "cases/$(basename "$f" .in)" "${f%.in}.out" "$(pick "1 4" "3")" "$f"
    done
    k=0
    for f in tests/hard/*.in; do
        [ -f "${f%.in}.out" ] || continue
        k=$((k + 1))
        all_suite || [ $((k % 6)) = 1 ] || continue
        ranks "hard/$(basename "$f" .in)" "${f%.in}.out" "3" "$f"
    done

    # the omp tests' scenes: every thread count they use, across 1 to 8 ranks (the quick suite: five
    # of them, one rank count each from 1 to 3; one_disk and mid_dense only made, for the checks below)
    combos=("1x7 2x3" "3x2 5x1" "8x1 2x7" "4x2 1x3" "6x1 3x3" "2x2 7x1")
    all_suite || combos=("2x2" "3x1" "1x3" "3x2" "2x1")
    quick_scenes="slow_print|fast_print|dense_gas|overlap_print|one_disk|mid_dense|mid_fast"
    k=0
    while read -r name args; do
        # shellcheck disable=SC2086
        tools/gen $args > "$M/$name.in"
        ./seq "$M/$name.in" --quiet > "$M/$name.ref"
        if all_suite || { [ "$name" != one_disk ] && [ "$name" != mid_dense ]; }; then
            ranks "$name" "$M/$name.ref" "${combos[k % ${#combos[@]}]}" "$M/$name.in"
            k=$((k + 1))
        fi
    done < <(grep -v '^#' tests/omp_scenes.txt | { if all_suite; then cat; else grep -E "^($quick_scenes) "; fi; })

    # random placement, standard input, --dump17, --substeps, a mixed scene
    printf '300\n400\n1\n15\nprint\n' > "$M/random.in"
    ./seq "$M/random.in" --quiet --seed 7 > "$M/random.ref"
    ranks "random placement --seed 7" "$M/random.ref" "$(pick "3 4x2" "3")" "$M/random.in" --seed 7
    # standard input reaches rank 0 only where mpirun passes it on with its end (Open MPI 5.0's mpirun
    # kept an MPI program's standard input open here: the program waited for more)
    if mpi_stdin "$M/one_disk.in" timeout 15 mpirun -np 1 ./mpi - --quiet 2> /dev/null | cmp -s - "$M/one_disk.ref"; then
        STDIN_FILE=$M/fast_print.in ranks "standard input" "$M/fast_print.ref" "3" -
    else
        skip "mpi standard input" "this mpirun does not pass on the end of its standard input"
    fi
    ./seq "$M/overlap_print.in" --quiet --dump17 > "$M/dump17.ref"
    ranks "--dump17" "$M/dump17.ref" "$(pick "2 5" "2")" "$M/overlap_print.in" --dump17
    tools/gen 400 --assignment --L 2000 --steps 20 > "$M/sub.in"
    ./seq "$M/sub.in" --quiet --substeps 2 > "$M/sub.ref"
    ranks "--substeps 2" "$M/sub.ref" "$(pick "3 2x2" "3")" "$M/sub.in" --substeps 2
    tools/gen 1500 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 10 > "$M/mixed.in"
    ./seq "$M/mixed.in" --quiet > "$M/mixed.ref"
    ranks "mixed scene" "$M/mixed.ref" "$(pick "1x2 5" "3")" "$M/mixed.in"
    # two fast disks among slow ones, crossing the strips for 200 steps: the fastest velocity (the
    # reach) must count the disks that leave a strip as well as those that stay
    tools/gen 400 --speed 0.5 --fast 0.005 --steps 200 --mode print > "$M/fast_few.in"
    ./seq "$M/fast_few.in" --quiet > "$M/fast_few.ref"
    ranks "two fast disks crossing the strips" "$M/fast_few.ref" "$(pick "2 5 8" "3")" "$M/fast_few.in"

    # the reach comes from the fastest speed a step late, times sqrt(2), the most a speed can grow in
    # a step: here disk 0's speed grows by sqrt(2) in step 1 (all of disk 1's, met along their normal,
    # added to its own, at right angles), and in step 2 it meets disk 2 across the cut between the two
    # strips, farther from the cut than 2r plus twice the first step's fastest speed
    printf '6\n100\n1\n3\nprint\n0 38.625 51.375 2.75 -2.75\n1 37.210786437626904 47.210786437626904 2.75 2.75\n2 57.125 50 -3.875 0\n3 43 10 0 0\n4 80 10 0 0\n5 90 10 0 0\n' > "$M/grow.in"
    ./seq "$M/grow.in" --quiet > "$M/grow.ref"
    ranks "a speed grown by sqrt(2), then a pair across the strips" "$M/grow.ref" "2 3" "$M/grow.in"

    # a step's messages go to the neighbours only: the strips within twice the reach, here more than
    # the two adjacent ones (8 ranks on a gas of 600 disks: strips narrower than twice the reach),
    # with seq's bytes
    if ! all_suite; then
        :
    elif run_mpi 8 1 inputs/dense_gas.in --stats --quiet > "$M/near.out" 2> "$M/near.err" &&
        cmp -s "$M/near.out" outputs/dense_gas.out &&
        near=$(sed -n 's/.*exchanged with in a step: up to \([0-9]*\)$/\1/p' "$M/near.err") &&
        [ -n "$near" ] && [ "$near" -ge 3 ] && [ "$near" -le 7 ]; then
        pass "mpi: neighbours beyond the adjacent strips ($near at 8 ranks), seq's bytes"
    else
        fail "mpi: neighbours beyond the adjacent strips" "neighbours '${near:-}'; $(head -c 300 "$M/near.err")"
    fi

    # the cuts between the strips: placed by count at the start, and with --balance K moved by the
    # ranks' measured times every K steps (disks migrate by the moved cuts); a gas crowded into the
    # box's lower-left quarter, where strips of equal width would leave most ranks without a disk
    for s in $(pick "mid_dense mid_fast overlap_print packed" "mid_fast"); do
        ranks "$s, --balance 1" "$M/$s.ref" "$(pick "3 5x2" "3")" "$M/$s.in" --balance 1
    done
    all_suite && ranks "mid_dense, --balance 3" "$M/mid_dense.ref" "4" "$M/mid_dense.in" --balance 3
    awk 'NR == 2 { $1 = 4 * $1 } { print }' "$M/mid_dense.in" > "$M/corner.in"
    ./seq "$M/corner.in" --quiet > "$M/corner.ref"
    ranks "a gas in one corner of the box" "$M/corner.ref" "$(pick "4 6x1" "4")" "$M/corner.in"
    read -r lo hi <<< "$(run_mpi 4 1 "$M/corner.in" --quiet --stats 2>&1 > /dev/null |
        sed -n 's/.*disks a rank at the end \([0-9]*\) to \([0-9]*\).*/\1 \2/p')"
    # 3000 disks within the first of 4 equal strips; by count each rank holds about 750 (less the
    # steps' drift)
    if [ "${lo:-0}" -ge 500 ] && [ "${hi:-9999}" -le 1000 ]; then
        pass "mpi: a gas crowded in one corner shared out by count ($lo to $hi disks a rank of 4)"
    else
        fail "mpi: a gas crowded in one corner" "${lo:-?} to ${hi:-?} disks a rank of 4"
    fi
    expect_mpi_error "mpi: --balance -1 refused" "balance" "$M/sub.in" --balance -1
    expect_error "seq: --balance refused" "unknown option '--balance'" ./seq "$M/sub.in" --balance 4

    # --pressure: the same bytes and the same pressure line as seq
    ./seq "$M/dense_gas.in" --quiet --pressure > "$M/pr.ref" 2> "$M/pr.err"
    ranks "--pressure" "$M/pr.ref" "3x2" "$M/dense_gas.in" --pressure
    run_mpi 4 1 "$M/dense_gas.in" --quiet --pressure > /dev/null 2> "$M/pr2.err"
    if [ "$(sed 's/^seq: //' "$M/pr.err")" = "$(sed 's/^mpi: //' "$M/pr2.err")" ] && [ -s "$M/pr.err" ]; then
        pass "mpi --pressure: seq's pressure line at 4 ranks"
    else
        fail "mpi --pressure" "seq '$(cat "$M/pr.err")', mpi '$(cat "$M/pr2.err")'"
    fi
    # --stats names the ranks and the rounds; --check finds nothing missing on fast and overlapping scenes
    if run_mpi 3 2 "$M/mid_dense.in" --stats > /dev/null 2> "$M/st.err" &&
        grep -q "3 ranks x 2 threads" "$M/st.err" && grep -q "pair tests" "$M/st.err"; then
        pass "mpi --stats"
    else
        fail "mpi --stats" "$(head -c 300 "$M/st.err")"
    fi
    # --stats times the input's phases where the ranks read a file, each no longer than the whole input;
    # from standard input rank 0 reads alone, and the phases are not given
    run_mpi 2 1 "$M/mid_dense.in" --quiet --stats > /dev/null 2> "$M/in.err"
    verdict=$(grep "input read and sent to the strips" "$M/in.err" | tr -d '(),;' | awk '{
        total = $7; n = 0; bad = ""; after = 0
        for (k = 1; k < NF; k++)
            if ($k == "rank:") after = 1
            else if (after && $k ~ /^(read|parsed|checked|strips)$/ && $(k + 1) ~ /^[0-9.]+$/) {
                n++
                if ($(k + 1) > total + 0.05) bad = bad " " $k
            }
        if (n != 4) print "found " n " phases"; else if (bad != "") print "longer than the input:" bad; else print "ok"
    }')
    mpi_stdin "$M/mid_dense.in" run_mpi 2 1 - --quiet --stats > /dev/null 2> "$M/in_stdin.err"
    if [ "$verdict" = ok ] && grep -q "input read and sent to the strips [0-9.]* s; step 0" "$M/in_stdin.err"; then
        pass "mpi --stats: the input's phases from a file, none from standard input"
    else
        fail "mpi --stats: the input's phases" "${verdict:-no line}: $(grep -h input "$M/in.err" "$M/in_stdin.err")"
    fi
    # --stats times the steps' phases on every rank: 70 steps are gathered in a chunk of 64 and the
    # rest; each phase's sum over the steps' slowest ranks is at least the ranks' mean, and equal to
    # it on one rank, whose steps are all its own
    tools/gen 3000 --fraction 0.2 --speed 0.5 --steps 70 --seed 5 > "$M/clock.in"
    for p in 1 3; do
        run_mpi "$p" 1 "$M/clock.in" --quiet --stats > /dev/null 2> "$M/clock.err"
        verdict=$(grep "phases outside MPI calls" "$M/clock.err" | tr -d '(),;' | awk -v p="$p" '{
            parts = 0; bad = ""
            for (k = 1; k < NF - 1; k++)
                if ($k ~ /^(halo|phase|choice|move|migration)$/ && $(k + 1) ~ /^[0-9.]+$/) {
                    parts++
                    if ($(k + 1) < $(k + 2) || (p == 1 && $(k + 1) != $(k + 2))) bad = bad " " $k
                }
            rank = $(NF - 4); got = $(NF - 3); of = $(NF - 1)
            if (parts != 5) print "found " parts " phases"
            else if (bad != "") print "slowest against mean wrong for" bad
            else if (of != 70 || got < 1 || got > 70 || rank < 0 || rank >= p) print "steps " got " of " of ", rank " rank
            else print "ok"
        }')
        if [ "$verdict" = ok ] && grep -q "phases inside MPI calls (the ranks' mean), seconds: halo" "$M/clock.err"; then
            pass "mpi --stats: the steps' phases on $p rank(s), 70 steps"
        else
            fail "mpi --stats: the steps' phases on $p rank(s)" "${verdict:-no line}: $(grep phases "$M/clock.err")"
        fi
    done
    for s in $(pick "mid_fast mid_overlap" "mid_fast"); do
        if run_mpi 3 1 "$M/$s.in" --quiet --check > /dev/null 2> "$M/ck.err"; then
            pass "mpi --check at 3 ranks: $s"
        else
            fail "mpi --check: $s" "$(head -c 300 "$M/ck.err")"
        fi
    done

    # the input in byte ranges: blank lines, CRLF, lines that straddle the ranges' edges, a last line
    # without a newline
    awk 'NR > 5 && NR % 7 == 0 { print "" } { print }' "$M/slow_print.in" > "$M/blank.in"
    ranks "blank lines between the particle lines" "$M/slow_print.ref" "$(pick "2 3 7" "3")" "$M/blank.in"
    sed 's/$/\r/' "$M/slow_print.in" > "$M/crlf.in"
    ./seq "$M/crlf.in" --quiet > "$M/crlf.ref"
    ranks "CRLF line ends" "$M/crlf.ref" "4" "$M/crlf.in"
    head -c -1 "$M/slow_print.in" > "$M/nonl.in"
    ranks "no newline at the end" "$M/slow_print.ref" "3" "$M/nonl.in"
    printf '2\n10\n1\n3\nprint\n\n\n\n0 2 2 1 0\n\n\n\n1 7 7 -1 0\n\n\n' > "$M/two.in"
    ./seq "$M/two.in" --quiet > "$M/two.ref"
    ranks "two disks, more ranks than lines" "$M/two.ref" "$(pick "5 8" "3")" "$M/two.in"

    # bad input, found by any rank: seq's message, once
    bad_case() { # NAME FILE: mpi at 3 ranks must print seq's message (program name aside), once
        local name=$1 f=$2 want
        want=$(./seq "$f" 2>&1 > /dev/null | sed 's/^seq: //')
        expect_mpi_error "mpi bad input ($name): seq's message at 3 ranks" \
            "^mpi: $(printf '%s' "$want" | sed 's/[][\.*^$(){}+?|]/\\&/g')\$" "$f"
    }
    printf '3\n10\n1\n5\nperf\n1 2 3\n' > "$M/bad.in"
    bad_case "a short line" "$M/bad.in"
    awk 'NR == 300 { $2 = "abc" } { print }' "$M/slow_print.in" > "$M/bad_late.in"
    bad_case "a bad real on the last rank's lines" "$M/bad_late.in"
    awk 'NR == 380 { $1 = 3 } { print }' "$M/slow_print.in" > "$M/dup.in"
    bad_case "an index given twice, far apart" "$M/dup.in"
    head -n 300 "$M/slow_print.in" > "$M/short.in"
    all_suite && bad_case "too few lines" "$M/short.in"
    { cat "$M/slow_print.in"; echo "400 1 1 0 0"; } > "$M/long.in"
    all_suite && bad_case "too many lines" "$M/long.in"
    awk 'NR == 200 { $3 = "1e999" } NR == 350 { $1 = 12 } { print }' "$M/slow_print.in" > "$M/two_bad.in"
    bad_case "two problems: the first line's wins" "$M/two_bad.in"
    printf '3\n10\n1\nfive\nperf\n' > "$M/bad_header.in"
    all_suite && bad_case "a bad header" "$M/bad_header.in"
    expect_mpi_error "mpi: --exact refused" "--exact is not supported by mpi" "$M/sub.in" --exact
    expect_mpi_error "mpi: --checkpoint in a missing folder refused" "cannot write" "$M/sub.in" --checkpoint "$M/none/ck"
    expect_mpi_error "mpi: --output into a missing folder refused" "cannot create the output" \
        "$M/sub.in" --output "$M/no/such/file"
    expect_error "seq: --output refused" "--output is not supported by seq" ./seq "$M/sub.in" --output "$M/x"

    # --output: every rank writes its lines at their offset; an older, longer file is replaced
    head -c 100000 /dev/urandom > "$M/written.out"
    if run_mpi 4 1 "$M/slow_print.in" --quiet --output "$M/written.out" > "$M/out" 2> "$M/err" &&
        [ ! -s "$M/out" ] && cmp -s "$M/written.out" "$M/slow_print.ref"; then
        pass "mpi --output: seq's bytes in the file at 4 ranks, nothing on stdout"
    else
        fail "mpi --output" "$(head -c 200 "$M/err")"
    fi
    ./seq "$M/mid_dense.in" --quiet > "$M/mid.ref"
    if run_mpi 3 2 "$M/mid_dense.in" --quiet --output "$M/written.out" && cmp -s "$M/written.out" "$M/mid.ref"; then
        pass "mpi --output: perf mode at 3 ranks x 2 threads"
    else
        fail "mpi --output (perf)"
    fi
fi
