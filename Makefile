# `make demo` and `make test` work on a fresh clone: they create .venv when it is missing and
# install the project with its dependencies first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[test,plot,bench]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/mocodec demo

test: $(STAMP)
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_foundation.py
	$(BIN)/python benchmarks/bench_measures.py
	$(BIN)/python benchmarks/bench_coding.py
	$(BIN)/python benchmarks/bench_lossless.py
	$(BIN)/python benchmarks/bench_codec_speed.py
	$(BIN)/python benchmarks/bench_seams.py
	$(BIN)/python benchmarks/bench_ratecontrol.py
	$(BIN)/python benchmarks/bench_perceptual.py --set amc
	$(BIN)/python benchmarks/bench_waveform.py --set amc

clean:
	rm -rf $(VENV) build src/*.egg-info .pytest_cache
	find src tests benchmarks -name __pycache__ -type d -prune -exec rm -rf {} +
