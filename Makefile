# The two commands of the README. Both set everything up first (scripts/setup.sh is idempotent).
.PHONY: setup demo test test-debian13 fuzz bench plugin-zip clean

setup:
	bash scripts/setup.sh

demo: setup
	.venv/bin/floodmesh demo --out demo_output

test: setup
	bash scripts/test.sh

# The same suite on Debian 13 (QGIS 3.40, Python 3.13, numpy 2.2) in a cached debootstrap root;
# needs root. .ci/run runs it after `make test`.
test-debian13:
	bash scripts/test_debian13.sh

# Wide exploration of the mesher: ten times the random PSLGs and rasters `make test` draws
# (FUZZ_PSLG=... etc. to change the counts); turn what it finds into fixed regression cases.
fuzz: setup
	FUZZ_PSLG=$${FUZZ_PSLG:-15000} FUZZ_RASTER=$${FUZZ_RASTER:-6000} FUZZ_RAW=$${FUZZ_RAW:-9000} \
	    bash scripts/test.sh tests/core/test_mesh_fuzz.py -q -p no:cacheprovider

bench: setup
	.venv/bin/pip install -q --disable-pip-version-check -c .venv/constraints.txt -e ".[test,bench]"
	.venv/bin/python benchmarks/run.py $(if $(ONLY),--only $(ONLY)) --write benchmarks/latest.md

plugin-zip: setup
	.venv/bin/python scripts/build_plugin_zip.py

clean:
	rm -rf build dist demo_output .pytest_cache
