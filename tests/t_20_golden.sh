# Golden outputs: every inputs/*.in through every backend, byte for byte against outputs/ (made by seq
# with `make golden`; inputs without particle lines use the default seed), and inputs/periodic/*.in
# against outputs/periodic/ with --periodic.
for f in inputs/*.in; do
    b=$(basename "$f" .in)
    on_backends "golden/$b" "outputs/$b.out" "$f"
done
# inputs/periodic/: the periodic box (SPEC.md 7), run with --periodic (mpi runs these in t_86)
for f in inputs/periodic/*.in; do
    b=$(basename "$f" .in)
    on_backends "golden/periodic/$b" "outputs/periodic/$b.out" "$f" --periodic
done
