# treegen — install, test, benchmark.
PYTHON ?= python3

.PHONY: install test bench clean gallery

install:
	$(PYTHON) -m pip install --quiet -e ".[dev]"
	-command -v pyenv >/dev/null 2>&1 && pyenv rehash
	cd tools && npm ci --silent --no-audit --no-fund

test:
	$(PYTHON) -m pytest

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
	@ls -l docs/gallery

clean:
	rm -rf build *.egg-info .pytest_cache tools/node_modules
