# io.c's %.8f formatter against printf over millions of values (tools/fmtcheck.c says which).
if out=$(./tools/fmtcheck 2>&1); then
    pass "format: $out"
else
    fail "format" "$(echo "$out" | head -3)"
fi
