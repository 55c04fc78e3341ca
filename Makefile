# The two commands of the README. Both work on a fresh machine with only python3.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp

.PHONY: demo test install benchmarks figures docs clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/jaxlimb demo

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist worksteal --durations=15 tests

benchmarks: $(STAMP)
	$(BIN)/python benchmarks/solvers.py

figures: $(STAMP)
	$(BIN)/python paper_figures/make_all.py

# The documentation site in build/site, with the notebooks executed first (their committed copies have no outputs).
docs: $(STAMP)
	rm -rf build/docs-executed && mkdir -p build/docs-executed/notebooks
	$(BIN)/jupyter nbconvert --to notebook --execute --ExecutePreprocessor.timeout=600 \
		--output-dir build/docs-executed/notebooks notebooks/*.ipynb
	JAXLIMB_DOCS_EXECUTED=build/docs-executed $(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) build *.egg-info
