# The two commands of the README. Both set everything up first (scripts/setup.sh is idempotent).
.PHONY: setup demo test bench plugin-zip clean

setup:
	bash scripts/setup.sh

demo: setup
	.venv/bin/floodmesh demo --out demo_output

test: setup
	bash scripts/test.sh

bench: setup
	.venv/bin/pip install -q --disable-pip-version-check -c constraints.txt -e ".[test,bench]"
	.venv/bin/python benchmarks/run.py $(if $(ONLY),--only $(ONLY))

plugin-zip: setup
	.venv/bin/python scripts/build_plugin_zip.py

clean:
	rm -rf build dist demo_output .pytest_cache
