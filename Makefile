# Two commands: `make demo` and `make test`. Both bootstrap .venv with Python 3.11.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= fingerfit-demo

.PHONY: demo test lint bench bench-accuracy clean

$(BIN)/fingerfit: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[stats,c3d,robot]"
	touch $@

.venv: $(BIN)/fingerfit

$(VENV)/.test-extras: $(BIN)/fingerfit
	$(BIN)/pip install --quiet -e ".[test,stats,c3d,robot,peers]"
	touch $@

# Test worker processes (pytest-xdist); tests of one module share a worker (its fixtures).
TEST_WORKERS ?= 2

demo: $(BIN)/fingerfit
	$(BIN)/fingerfit demo --out $(OUT)

test: $(VENV)/.test-extras
	@command -v chromium >/dev/null 2>&1 || (command -v apt-get >/dev/null 2>&1 && \
	  (apt-get install -y -qq chromium >/dev/null 2>&1 || \
	   (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq chromium >/dev/null 2>&1)) || \
	  echo "chromium not installed: the report screenshot test will be skipped")
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check --quiet src tests bench
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadscope

# CLUSTER_SUBJECTS: the simulated cohort on a local Dask cluster (0: skip; 1000 take 21-40 min here).
CLUSTER_SUBJECTS ?= 1000
bench: $(VENV)/.test-extras
	$(BIN)/python bench/speed.py --json bench/speed.json --cluster-subjects $(CLUSTER_SUBJECTS)

bench-accuracy: $(VENV)/.test-extras
	$(BIN)/python bench/accuracy.py --json bench/accuracy.json

clean:
	rm -rf $(VENV) $(OUT) build dist src/*.egg-info .pytest_cache .ruff_cache
