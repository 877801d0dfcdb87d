#!/usr/bin/env bash
# Set up, lint and run the test suite (the README's second quick-start command).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check src tests benchmarks
.venv/bin/python -m pytest -q tests
