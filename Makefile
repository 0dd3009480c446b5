# backlashkit: the two commands of the quick start, and a few more.
#   make demo   set up .venv (if needed) and run the main job: paper A's experiment
#               simulated and plotted, paper B's example reproduced (outputs in out/)
#   make test   set up .venv (if needed) and run every check CI runs
# Needs python3 (>= 3.10) with venv, a Rust toolchain (cargo, with clippy and rustfmt)
# and access to PyPI and crates.io.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup demo test test-rust test-python lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# Rebuilt when the sources or the project metadata change.
$(STAMP): $(BIN)/python pyproject.toml Cargo.toml crates/core/Cargo.toml crates/py/Cargo.toml \
          $(wildcard crates/*/src/*.rs crates/*/src/*/*.rs)
	$(BIN)/python -m pip install --quiet --upgrade pip "maturin>=1.7,<2"
	VIRTUAL_ENV=$(CURDIR)/$(VENV) $(BIN)/maturin develop --release --extras test,bench
	touch $(STAMP)

setup: $(STAMP)

demo: setup
	mkdir -p out
	$(BIN)/backlashkit simulate examples/paper_drive.toml --experiment step-down \
	    --amplitude 0.157 --hold 40 --out out/paper_experiment.csv \
	    --plot out/paper_experiment.png --force
	$(BIN)/backlashkit reproduce tao1995 --report out/tao1995 --json-out out/tao1995.json --force

test: setup test-rust lint test-python

test-rust:
	cargo test --workspace --release

lint: setup
	cargo fmt --all -- --check
	cargo clippy --workspace --release --all-targets -- -D warnings
	$(BIN)/ruff check python tests benchmarks

test-python: setup
	$(BIN)/python -m pytest -n auto

bench: setup
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_control.py

clean:
	rm -rf $(VENV) out target
