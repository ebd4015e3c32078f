# The code's layers (io.h, README's table): every C file calls only the files listed before it here,
# so no two files call each other, directly or round a cycle. Each file is compiled on its own and
# its undefined symbols (nm -u) are matched with the symbols the others define. cuda.cu (nvcc, a
# minute) is left out: it calls only the I/O layer and state.c.
LAYERS="state exact output place input checkpoint io seq omp_team omp_paths omp_broad omp_exact omp
mpi_comm mpi_io mpi"
L=$TMP/layers
mkdir -p "$L"
if ! command -v nm > /dev/null 2>&1; then
    skip "layers" "no nm (binutils)"
    return
fi
layer_files=""
for f in $LAYERS; do
    cc=${CC:-cc}
    case $f in mpi*) cc=mpicc ;; esac
    if ! command -v "$cc" > /dev/null 2>&1; then continue; fi
    if ! "$cc" -std=c99 -fopenmp -c "$f.c" -o "$L/$f.o" 2> "$L/$f.err"; then
        fail "layers: $f.c compiles alone" "$(head -c 200 "$L/$f.err")"
        continue
    fi
    nm --defined-only "$L/$f.o" | awk '$2 ~ /[TDRBC]/ { print $3 }' | sort -u > "$L/$f.def"
    nm -u "$L/$f.o" | awk '{ print $2 }' | sort -u > "$L/$f.undef"
    layer_files="$layer_files $f"
done
# every call between files, as "CALLER CALLEE"
for a in $layer_files; do
    for b in $layer_files; do
        [ "$a" = "$b" ] && continue
        comm -12 "$L/$a.undef" "$L/$b.def" | grep -q . && echo "$a $b"
    done
done > "$L/calls"
upward=$(awk -v order="$layer_files" '
    BEGIN { n = split(order, f, " "); for (k = 1; k <= n; k++) at[f[k]] = k }
    at[$2] > at[$1] { printf "%s calls %s; ", $1, $2 }' "$L/calls")
if [ ! -s "$L/calls" ]; then
    fail "layers" "no calls between files found"
elif [ -z "$upward" ]; then
    pass "layers: $(wc -l < "$L/calls") calls between $(echo $layer_files | wc -w) files, each to a file below"
else
    fail "layers: a file calls one above it" "$upward"
fi
