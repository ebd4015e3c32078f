# output.c's %.8f formatter against printf over millions of values (tools/fmtcheck.c says which); the
# quick suite a tenth of them.
fmt_count=1000000
all_suite || fmt_count=100000
if out=$(./tools/fmtcheck "$fmt_count" 2>&1); then
    pass "format: $out"
else
    fail "format" "$(echo "$out" | head -3)"
fi
