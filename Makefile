# The two commands a new user needs: `make demo` and `make test` (each sets itself up first).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO_OUT := out/demo

.PHONY: setup bytecode demo test lint regress bench bench-real repeatability clean

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test,lab,dask]'
	touch $(STAMP)

## compile the package's bytecode: pip does it when it installs a wheel, not for an editable
## install, and with PYTHONDONTWRITEBYTECODE set (as on our machines) every command would compile
## every module again at start-up (about 30 ms of each `scalematch LOW HIGH`;
## docs/design/SPEED.md, "Start-up: import only what a command needs")
bytecode: $(STAMP)
	$(BIN)/python -m compileall -q scalematch > /dev/null

## match the demo pair shipped in data/ and write its outputs to out/demo/
demo: $(STAMP) bytecode
	$(BIN)/scalematch data/demo_low.png data/demo_high.png --out-dir $(DEMO_OUT) --json $(DEMO_OUT)/result.json; \
	  code=$$?; echo "exit code $$code (0 = matched, 1 = no reliable match); outputs in $(DEMO_OUT)/"; test $$code -le 1

## run the test suite (tests needing ../shared skip when it is absent)
test: $(STAMP) bytecode
	$(BIN)/python -m pytest -q

## check the code with ruff (the rules: pyproject.toml, [tool.ruff])
lint: $(STAMP)
	$(BIN)/ruff check .

## the regression gate (needs ../shared): every kind of pair, both orders, against the baseline
## committed in tests/regress/baseline.json; exit 1 on a pair lost or a new wrong claim. About
## 15 minutes; SLICE=ci runs the zoom pairs only (about 3 minutes, as .ci/run does); UPDATE=1
## writes this run into the baseline once a change is accepted; TREE=DIR runs the matcher of
## another checkout (docs/REGRESS.md)
regress: $(STAMP)
	$(BIN)/scalematch lab regress $(if $(SLICE),--slice $(SLICE)) \
	  $(if $(UPDATE),--update --write-doc docs/REGRESS.md) \
	  $(if $(TREE),--tree $(TREE)) $(if $(IF_SHARED),--if-shared)

## the benchmark against the peers (needs ../shared); writes docs/results/BENCHMARKS.md
bench: $(STAMP)
	$(BIN)/scalematch lab bench --out-dir bench-out --write-doc docs/results/BENCHMARKS.md

## the real-pair benchmark (needs ../shared): Oxford both ways, tilted and swapped pairs; writes its
## tables into docs/results/BENCHMARKS.md
bench-real: $(STAMP)
	$(BIN)/scalematch lab real-pairs --write-doc docs/results/BENCHMARKS.md

## the repeatability of standard vs scale-adapted Harris (needs ../shared); writes
## docs/results/repeatability.csv, .json and .png (docs/results/REPEATABILITY.md explains them)
repeatability: $(STAMP)
	$(BIN)/scalematch lab repeatability --out-dir docs/results

clean:
	rm -rf $(VENV) out bench-out
