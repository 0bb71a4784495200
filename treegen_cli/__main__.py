"""`python -m treegen_cli` runs the CLI (used by the benchmarks and tests)."""

from .cli import main

main()
