# Long inputs are parsed in chunks of about 64 kB on several threads (io.c). A 20000-disk file spans
# about 14 chunks: its disks must be read exactly, in any line order and around blank lines, and each
# kind of error must be reported on the line a line-by-line reader meets first, whatever the thread
# count. Expected lines and messages are computed here from the file itself, not by the programs.

P=$TMP/parse
mkdir -p "$P"
N=20000
tools/gen $N --fraction 0.2 --speed 3 --steps 0 --mode print --seed 21 > "$P/base.in"
head -n 5 "$P/base.in" > "$P/head"
tail -n +6 "$P/base.in" > "$P/disks"
last=$((N + 5))

# the programs run below: seq, omp at 1, 3 and 7 threads, cuda where a GPU answers
parse_runs() {
    echo "seq ./seq"
    for t in 1 3 7; do echo "omp$t ./omp --threads $t"; done
    if have_gpu; then echo "cuda ./cuda"; fi
}

# Step 0 of a shuffled file with blank and indented lines: each disk as the input gave it (%.8f of the
# parsed value; -0 written as 0 on both sides, where printf conventions could differ).
{
    cat "$P/head"
    awk '{ line[NR] = $0 } END {
        for (i = NR; i >= 1; i--) {
            if (i % 997 == 0) print ""
            print (i % 3 ? "" : "  ") line[i]
        }
    }' "$P/disks"
} > "$P/shuffled.in"
# step 0, then the final state of a run of 0 steps: step 0 again, with its collision counts
awk '{ printf "0 %d %.8f %.8f %.8f %.8f\n", $1, $2, $3, $4, $5 }' "$P/disks" |
    sed 's/-\(0\.00000000\)/\1/g' > "$P/step0"
{ cat "$P/step0"; sed 's/$/ 0 0/' "$P/step0"; } > "$P/expected"
while read -r name cmd; do
    if $cmd "$P/shuffled.in" --quiet > "$P/out" 2> "$P/err" &&
        sed 's/-\(0\.00000000\)/\1/g' "$P/out" | cmp -s - "$P/expected"; then
        pass "parse chunks: shuffled $N disks read exactly ($name)"
    else
        fail "parse chunks: shuffled $N disks read exactly ($name)" "$(head -c 200 "$P/err")"
    fi
done < <(parse_runs)

# with_lines FILE SED_SCRIPT: base.in edited by sed (line numbers are file lines)
with_lines() { sed "$2" "$P/base.in" > "$P/$1.in"; }
index_on() { sed -n "${1}p" "$P/base.in" | cut -d' ' -f1; }

# expect_message NAME MESSAGE: every program stops on NAME.in with exactly that stderr line
expect_message() {
    local name=$1 message=$2 prog cmd
    while read -r prog cmd; do
        local expected="${cmd%% *}: $P/$name.in:$message"
        expected=${expected#./}
        if $cmd "$P/$name.in" > "$P/out" 2> "$P/err"; then
            fail "parse chunks: $name ($prog)" "exit 0"
        elif [ -s "$P/out" ] || [ "$(cat "$P/err")" != "$expected" ]; then
            fail "parse chunks: $name ($prog)" "stderr '$(head -c 200 "$P/err")', expected '$expected'"
        else
            pass "parse chunks: $name ($prog)"
        fi
    done < <(parse_runs)
}

with_lines first '6s/^\([0-9]*\) [^ ]*/\1 zz/'
expect_message first "6: x is not a number (found 'zz')"
with_lines middle '10006s/ [^ ]*$/ 1e999/'
expect_message middle "10006: vy is out of range (found '1e999')"
with_lines last "${last}s/ [^ ]* [^ ]*$/ 7/"
expect_message last "$last: expected 5 fields 'i x y vx vy' (found 4)"

# an index given twice: its first line lies many chunks earlier
with_lines twice "15000s/^[0-9]*/$(index_on 200)/"
expect_message twice "15000: index $(index_on 200) given twice (first on line 200)"
# the earlier of two errors in different chunks wins, whichever chunk a thread finishes first
with_lines two_errors "12000s/^[0-9]*/$(index_on 300)/; 18000s/ [^ ]*$/ nan/"
expect_message two_errors "12000: index $(index_on 300) given twice (first on line 300)"
with_lines two_errors_late "9000s/ [^ ]*$/ nan/; 19000s/^[0-9]*/$(index_on 30)/; 19500s/ [^ ]*$/ zz/"
expect_message two_errors_late "9000: vy must be a finite number (found 'nan')"
# on one line the index is checked before the numbers
with_lines dup_and_nan "16000s/^[0-9]* \([^ ]*\) [^ ]*/$(index_on 9) \1 nan/"
expect_message dup_and_nan "16000: index $(index_on 9) given twice (first on line 9)"
# one line more than N: the count comes before the index check on the extra line
with_lines extra "1s/.*/$((N - 1))/"
expect_message extra "$last: more particle lines than N = $((N - 1)) (found another one)"
# a missing line is reported after the last line, naming the smallest missing index
with_lines missing "7000d"
expect_message missing "$last: expected $N particle lines, found $((N - 1)) (index $(index_on 7000) is missing; end of input)"
# a byte 0 is found before the fields of its line are looked at
with_lines zero_byte "17000s/ / \x00/"
expect_message zero_byte "17000: unexpected byte 0 in the text (found one at column $(($(sed -n 17000p "$P/base.in" | cut -d' ' -f1 | wc -c) + 1)))"
