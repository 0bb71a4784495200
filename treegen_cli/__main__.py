"""`python -m treegen_cli` runs the CLI (used by the benchmarks and tests)."""

from .entry import main

main()
