# flowgap — every target sets up .venv from the project's own files first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: venv test demo bench lint clean mutation

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --no-compile -e '.[dev]'
	@# pip compiles the installed packages one file at a time (84 s of a 150 s install on 2 cores); compileall
	@# does it on every core.  Like pip, it leaves files it cannot compile (torch ships Python 3.12-only tests).
	$(BIN)/python -m compileall -q -j 0 "$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" \
		> $(VENV)/compileall.log 2>&1 || true
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

demo: $(STAMP)
	$(BIN)/python -m scenes build window1_brick
	$(BIN)/python -m tools.launch --scene window1_brick --result runs/demo-verdict.json

bench: $(STAMP)
	$(BIN)/python -m tools.bench

# Mutation testing (not part of test): mutmut over the pure-core modules, report in docs/mutation.md.
# MUTATION_TARGETS=companion.servo for one; all of them takes hours on 2 cores.
MUTATION_TARGETS ?= all
mutation: $(STAMP)
	nice -n 10 $(BIN)/python -m tools.mutation --run $(MUTATION_TARGETS) -o docs/mutation.md

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
