# The worked examples of the specification (tests/cases/*.in with their exact .out), every backend.
for f in tests/cases/*.in; do
    name=$(basename "$f" .in)
    same_bytes "cases/$name seq" "${f%.in}.out" ./seq "$f" --quiet
    for t in 1 2 3 7; do
        same_bytes "cases/$name omp $t threads" "${f%.in}.out" ./omp "$f" --quiet --threads "$t"
    done
    if have_gpu; then
        same_bytes "cases/$name cuda" "${f%.in}.out" ./cuda "$f" --quiet
    else
        skip "cases/$name cuda" "no GPU"
    fi
done
