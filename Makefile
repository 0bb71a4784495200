# treegen — install, test, benchmark.
PYTHON ?= python3

.PHONY: install test lint bench clean gallery

install:
	$(PYTHON) -m pip install --quiet -e ".[dev]"
	-command -v pyenv >/dev/null 2>&1 && pyenv rehash
	cd tools && npm ci --silent --no-audit --no-fund
	@# usd-core 24.11's ComplianceChecker(arkit=True) for the .usdz AR check (gone from usd-core 26); its test skips without it
	-$(PYTHON) tests/arkit_check.py --install
	@# Godot 3.2 headless (tests/clients.py): only as root with apt-get, only when missing; its tests skip without it
	@if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ] && ! command -v godot3-server >/dev/null 2>&1; then \
		echo "apt-get install godot3-server"; \
		log=$$(mktemp); \
		if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends godot3-server; } >$$log 2>&1; then \
			tail -n 5 $$log; echo "warning: godot3-server not installed; the Godot client tests will be skipped"; fi; \
		rm -f $$log; \
	fi

test: lint
	$(PYTHON) -m pytest

# ruff's lint rules and a type check of the public stage and exchange modules (pyproject.toml)
lint:
	$(PYTHON) -m ruff check treegen_cli tests bench
	$(PYTHON) -m ruff format --check treegen_cli tests bench
	$(PYTHON) -m mypy

bench:
	$(PYTHON) bench/generate_bench.py
	@for b in bench/make_bench.py bench/wind_bench.py bench/lod_bench.py bench/forest_bench.py; do \
		if [ -f $$b ]; then echo "== $$b"; $(PYTHON) $$b; fi; done

# README pictures: every bundled species at 320 px and one wind loop (headless, EGL)
GALLERY_SPECIES = $(basename $(notdir $(wildcard species/*.txt)))
gallery:
	@mkdir -p docs/gallery
	@for s in $(GALLERY_SPECIES); do \
		treegen preview species/$$s.txt -o docs/gallery/$$s.png --size 320 --png-colors 256 -q || exit 1; \
		echo "docs/gallery/$$s.png"; done
	treegen preview species/quaking_aspen.txt --animate docs/gallery/quaking_aspen_wind.gif --size 240 --fps 10 -q
	treegen preview species/weeping_willow.txt --animate docs/gallery/weeping_willow_wind.gif --size 240 --fps 10 -q
	treegen preview examples/forest_1000.json -o docs/gallery/forest_1000.png --size 640x360 --png-colors 256 -q
	@ls -l docs/gallery

clean:
	rm -rf build *.egg-info .pytest_cache tools/node_modules
