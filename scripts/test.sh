#!/usr/bin/env bash
# Set up, lint and run the test suite (the README's second quick-start command).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check src tests benchmarks
# two workers (pytest-xdist), each test file whole on one of them: module fixtures and
# caches computed once, the tests of one file never run against each other
.venv/bin/python -m pytest -q -n 2 --dist loadfile tests
