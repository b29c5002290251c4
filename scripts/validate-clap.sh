#!/usr/bin/env bash
# The installed CLAP plugin through clap-validator's whole suite, each test in a process of its
# own as the validator runs them by default, with a table of every test's time against the
# validator's limit of 45 s a test. Exit status 1 if a test fails or crashes, or if one takes
# more than half the limit (the room a host's scan or a second job on the machine needs). Not
# part of CI: clap-validator is not on crates.io; build it from its repository
# (https://github.com/free-audio/clap-validator, `cargo build --release`) and put it on PATH or
# name it in CLAP_VALIDATOR. About 30 s.
#
#   bash scripts/install-plugins.sh && bash scripts/validate-clap.sh [PLUGIN.clap]
set -euo pipefail
plugin=$(realpath "${1:-$HOME/.clap/unacorda.clap}")
validator=${CLAP_VALIDATOR:-clap-validator}
[ -f "$plugin" ] || { echo "no plugin at $plugin (bash scripts/install-plugins.sh builds it)"; exit 2; }
command -v "$validator" > /dev/null || { echo "no clap-validator (CLAP_VALIDATOR or PATH): see the top of $0"; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The validator's progress goes to its log, shown if it ends without a report.
"$validator" validate --json --hide-output "$plugin" > "$work/report.json" 2> "$work/log" ||
  [ -s "$work/report.json" ] || { tail -20 "$work/log"; exit 1; }
python3 - "$work/report.json" <<'PY'
import json, sys

LIMIT_S = 45.0
PASSED = ("success", "skipped", "warning")
with open(sys.argv[1]) as f:
    results = json.load(f)["results"]
rows = []
for r in results:
    ((_, test),) = r["test"].items()
    seconds = r["duration"]["secs"] + r["duration"]["nanos"] * 1e-9
    status = r["status"]
    rows.append((seconds, test["test"], status["code"], status.get("details") or ""))
rows.sort(reverse=True)
print(f"{'test':45} {'status':8} {'time':>8}  (limit {LIMIT_S:.0f} s a test)")
for seconds, name, code, details in rows:
    mark = "  <- over half the limit" if seconds > LIMIT_S / 2 else ""
    print(f"{name:45} {code:8} {seconds:7.2f}s{mark}")
    if code not in ("success", "skipped"):
        print(f"    {details}")
codes = sorted({row[2] for row in rows})
print(", ".join(f"{sum(1 for row in rows if row[2] == c)} {c}" for c in codes), f"of {len(rows)} tests")
bad = [row for row in rows if row[2] not in PASSED or row[0] > LIMIT_S / 2]
sys.exit(1 if bad else 0)
PY
