# treegen — install, test, benchmark.
PYTHON ?= python3

.PHONY: install test bench clean

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

clean:
	rm -rf build *.egg-info .pytest_cache tools/node_modules
