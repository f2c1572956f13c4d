#!/usr/bin/env bash
# Test-only dependencies that pip's extras cannot express:
# - the official SoccerNet evaluator (the oracle of the metric tests), without its heavy deps;
# - Debian's chromium for the browser tests (never `playwright install`: it downloads a browser).
set -euo pipefail
pip install --no-deps "SoccerNet==0.2.0"
if ! command -v chromium >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
    apt-get update -qq && apt-get install -y -qq chromium >/dev/null
  else
    echo "chromium not found and cannot be installed here: the browser tests will be skipped" >&2
  fi
fi
