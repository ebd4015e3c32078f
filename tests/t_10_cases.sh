# The worked examples of the specification (tests/cases/*.in with their exact .out), every backend.
for f in tests/cases/*.in; do
    on_backends "cases/$(basename "$f" .in)" "${f%.in}.out" "$f"
done
