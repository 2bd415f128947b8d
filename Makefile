# make demo  - set everything up and run the main job on the built-in simulated yard
# make test  - set everything up and run the tests
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: demo test setup setup-test clean

demo: setup
	$(BIN)/i2v-loc sim --vehicle man_tgx --scenario docking --seed 1 --duration 30 \
		--out $(OUT)/demo --preview $(OUT)/demo/preview.png
	@echo "recording and preview written to $(OUT)/demo"

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
