#!/usr/bin/env bash
# Set up and write the report of the paper's prototype (the README's first command).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/opticalstamp report --design paper2016 --out report "$@"
echo "open report/index.html"
