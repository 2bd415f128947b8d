# make demo  - set everything up and run the main job (the yard service) on the built-in simulated yard
# make test  - set everything up and run the tests
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= out
PORT   ?= 8000

.PHONY: demo test setup setup-test clean

# The yard service on the simulated yard (MAN TGX docking in a loop), dashboard on
# http://127.0.0.1:8000/. Parameter changes persist in $(OUT)/yard-params.yaml; set
# I2V_LOC_API_TOKEN to allow them. Stop with Ctrl-C.
demo: setup
	@mkdir -p $(OUT)
	$(BIN)/i2v-loc serve --source sim:docking --params $(OUT)/yard-params.yaml --port $(PORT)

test: setup-test
	$(BIN)/python -m pytest

setup: $(VENV)/.installed

setup-test: $(VENV)/.installed-test

$(VENV)/.installed: pyproject.toml scripts/system-deps.sh
	bash scripts/system-deps.sh
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "i2v-loc needs Python >= 3.11")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: $(VENV)/.installed
	bash scripts/system-deps.sh --test
	$(BIN)/pip install --quiet -e '.[test,distributed]'
	touch $@

clean:
	rm -rf $(VENV) $(OUT) *.egg-info
