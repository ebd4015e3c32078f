# Random placement (SPEC.md 1) runs in speculative windows on all threads (io.c, generate): it must give
# every disk the draws that placing the disks one by one gives. The digests below are of the outputs
# (S = 0: step 0 and the final state, positions and velocities) made by the one-by-one loop (tree
# 3451787, before the windows), double and float: a dilute scene whose first tries collide now and then
# (1e5 and 3e5 disks), and dense ones where most windows end early (area fractions 0.44 and 0.016).
# Regenerate only on purpose, from a build that places the disks one by one.
while read -r n L r seed want want_f32; do
    printf '%s\n%s\n%s\n0\nperf\n' "$n" "$L" "$r" > "$TMP/place.in"
    progs=(seq "omp --threads 1" "omp --threads 3" "omp --threads 7" seq_f32 "omp_f32 --threads 3")
    if have_gpu; then progs+=(cuda cuda_f32); else skip "placement $n disks: cuda" "no GPU"; fi
    for prog in "${progs[@]}"; do
        case $prog in *f32*) expect=$want_f32 ;; *) expect=$want ;; esac
        # shellcheck disable=SC2086
        got=$(./$prog "$TMP/place.in" --seed "$seed" --quiet | md5sum | cut -c1-32)
        if [ "$got" = "$expect" ]; then
            pass "placement $n disks, L = $L, seed $seed, $prog: the one-by-one loop's disks"
        else
            fail "placement $n disks, L = $L, seed $seed, $prog" "digest $got, expected $expect"
        fi
    done
done <<'SCENES'
100000 20000 1 1 d7b659bdca626cf7a3af4ffe1ebe10ac 215387acca1bd93dd4635b7def95b628
2000 120 1 1 ca65ef630b9c0c8c10b65cd1f657a3b9 300c93390385fcd6392691d87efe2050
20000 2000 1 7 baa89471f97189b974f83987a669a7bc 1e5cb5fd3592601996813c91914c0267
300000 40000 1 3 44de9c9dcdb7a07028b38a31f598ed9a 284ca261e85dc4a150eda7381a1f9f92
SCENES
