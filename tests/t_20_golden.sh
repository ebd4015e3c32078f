# Golden outputs: every inputs/*.in through every backend, byte for byte against outputs/ (made by seq
# with `make golden`; inputs without particle lines use the default seed).
for f in inputs/*.in; do
    b=$(basename "$f" .in)
    on_backends "golden/$b" "outputs/$b.out" "$f"
done
