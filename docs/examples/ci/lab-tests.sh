#!/usr/bin/env bash
# A user's CI job against the emulated lab (docs/testing.md, "A CI job"): the byte-stream
# regression against the golden, the shell smoke test with --expect, then the pytest suite
# (expect tests on the live lab, cassette tests with no lab). Each step fails the job with
# its own exit status; the diff is kept as an artifact for the job's page.
#   GOLDEN     the golden recording (default tests/golden/office-seed1)
#   TESTS      the pytest folder (default tests)
#   ARTIFACTS  where the run and its diff go (default lab-artifacts)
set -euo pipefail
golden=${GOLDEN:-tests/golden/office-seed1}
tests=${TESTS:-tests}
artifacts=${ARTIFACTS:-lab-artifacts}
mkdir -p "$artifacts"

# 1. today's bytes against the golden: the same scenario, seed and duration it was made with
navtwin emulate --scenario office --seed 1 --speed max --duration 2 \
    --record "$artifacts/run" --overwrite --quiet > /dev/null
if ! navtwin diff "$golden" "$artifacts/run" > "$artifacts/diff.txt"; then
    cat "$artifacts/diff.txt"
    navtwin diff "$golden" "$artifacts/run" --json > "$artifacts/diff.json" || true
    echo "the lab's bytes differ from $golden (above); if the change is meant, record the golden again" >&2
    exit 1
fi

# 2. smoke: the board streams, every anchor answers, no exchange times out (exit 3 if not)
navtwin emulate --scenario office --speed max --quiet --expect sins:seq=300 \
    --expect nanoloc:anchor=2,status=0x0F --fail-on nanoloc:status=0x40 --timeout 30 > /dev/null

# 3. the host code's own tests: expect on the live lab, cassettes without it
python -m pytest -q -p no:cacheprovider "$tests"
