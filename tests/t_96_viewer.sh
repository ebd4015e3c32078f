# The viewer (viewer/index.html) in a real headless browser (chromium-headless-shell, driven over the
# DevTools protocol by tools/browser.py): bundled runs shown at a given step, drawn both ways (2D
# canvas and WebGL), with the colours at the disks' centres and at empty places checked against the
# output; clicks, keys, playback, the file pickers, an HTTP server; bad outputs give a message. Then
# `make demo` and its run in the viewer. SKIP where no such browser can be had (.ci/run installs it).
V=$TMP/viewer
mkdir -p "$V"
viewer_skip=""
if ! command -v python3 > /dev/null 2>&1; then
    viewer_skip="no python3"
elif ! python3 -c 'import sys; sys.path.insert(0, "tools"); import browser; sys.exit(0 if browser.find_chromium() else 1)'; then
    viewer_skip="no chromium-headless-shell (apt-get install chromium-headless-shell)"
fi

if [ -n "$viewer_skip" ]; then
    skip "viewer" "$viewer_skip"
else
    # each line of the checker is one check here
    while IFS= read -r line; do
        case $line in
            "PASS "*) pass "${line#PASS }" ;;
            "FAIL "*) fail "${line#FAIL }" ;;
            *) echo "$line" ;;
        esac
    done < <(timeout 300 python3 tests/viewer_check.py "$V" 2>&1 || echo "FAIL viewer: tests/viewer_check.py stopped (status $?)")

    # make demo: the run it writes opens at its last step
    if ! make -s demo > "$V/demo.log" 2>&1; then
        fail "viewer/make demo" "$(tail -n 3 "$V/demo.log" | tr '\n' ' ')"
    elif ! grep -q "index.html?in=demo.in&src=demo.out" "$V/demo.log"; then
        fail "viewer/make demo" "no line saying how to open the run: $(head -c 300 "$V/demo.log")"
    else
        status=$(python3 tools/browser.py eval \
            "file://$PWD/viewer/index.html?in=demo.in&src=demo.out&step=300" \
            "document.body.dataset.ready + ' ' + document.getElementById('status').textContent" 2>&1)
        if [ "$status" = '"1 step 300 of 300, 2000 disks"' ]; then
            pass "viewer/make demo: viewer/demo.out opens at step 300 of 300, 2000 disks"
        else
            fail "viewer/make demo" "the viewer says $status"
        fi
    fi
fi
