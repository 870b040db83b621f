# `make demo` and `make test` work on a fresh clone: they create .venv when it is missing and
# install the project with its dependencies first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
THREE_VERSION := 0.187.0
VENDOR := src/mocodec/data/three

.PHONY: demo test test-fast lint bench bench-suite vendor api clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# the package with its own dependencies (what the demo needs), then the kernels of the demo's
# codec compiled once (numba caches them)
BASE := $(VENV)/.installed-base
$(BASE): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e .
	$(BIN)/mocodec warmup kinwave
	touch $(BASE)

# every extra, for the tests, benchmarks and tools
$(STAMP): $(BASE) pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[test,plot,bench,stream,view,lint,formats,zarr,docs]"
	touch $(STAMP)

# every codec's kernels, for the tests and benchmarks
WARM := $(VENV)/.warm
$(WARM): $(STAMP)
	$(BIN)/mocodec warmup
	touch $(WARM)

# the viewer's three.js (and the glTF loader the format tests load our files with) is checked in
# with its licence under $(VENDOR), so a wheel carries it; this fetches the pinned version from
# npm again (npm checks its integrity), after THREE_VERSION changes
vendor:
	rm -rf $(VENDOR).tmp && mkdir -p $(VENDOR).tmp
	cd $(VENDOR).tmp && npm pack --silent three@$(THREE_VERSION) > /dev/null && tar xzf three-$(THREE_VERSION).tgz
	mkdir -p $(VENDOR)/addons/controls $(VENDOR)/addons/loaders $(VENDOR)/addons/utils
	cp $(VENDOR).tmp/package/build/three.core.js $(VENDOR).tmp/package/LICENSE $(VENDOR)/
	cp $(VENDOR).tmp/package/examples/jsm/controls/OrbitControls.js $(VENDOR)/addons/controls/
	cp $(VENDOR).tmp/package/examples/jsm/utils/BufferGeometryUtils.js \
	   $(VENDOR).tmp/package/examples/jsm/utils/SkeletonUtils.js $(VENDOR)/addons/utils/
	cp $(VENDOR).tmp/package/build/three.module.js $(VENDOR)/
	cp $(VENDOR).tmp/package/examples/jsm/loaders/GLTFLoader.js $(VENDOR)/addons/loaders/
	rm -rf $(VENDOR).tmp

demo: $(BASE)
	$(BIN)/mocodec demo

# the JavaScript tests (Node's own runner; tests/js/register.mjs resolves 'three' to the vendored copy)
JS_TESTS := node --import ./tests/js/register.mjs --test tests/js/

# the whole suite, on two workers (the machine's cores; about five minutes)
test: $(WARM)
	$(JS_TESTS)
	$(BIN)/python -m pytest -n 2 --dist loadgroup

# the edit-test loop: everything but the slow tier (fuzzing, corruption sweeps, every shared
# clip), the browser and the network (relay, NATS) tests
test-fast: $(WARM)
	$(JS_TESTS)
	$(BIN)/python -m pytest -n auto -m "not slow and not browser and not network"

# ruff (lint and format check) and mypy
lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks
	$(BIN)/mypy

# every benchmark script of benchmarks/ (speed and rate-distortion of each issue), one after another
bench: $(WARM)
	for script in foundation measures coding lossless codec_speed speed seams ratecontrol kinwave kinwave_ablation fixed_cost \
	              invariance bound_usage search live live_page formats relay_tick js_moc primitives rhythmic model_based hostile; do \
		$(BIN)/python benchmarks/bench_$$script.py || exit 1; done
	$(BIN)/python benchmarks/bench_perceptual.py --set amc
	$(BIN)/python benchmarks/bench_waveform.py --set amc
	$(BIN)/python benchmarks/fig_6_2_vmse.py
	$(BIN)/python benchmarks/bench_streaming.py
	$(BIN)/python benchmarks/bench_capture.py
	$(BIN)/python benchmarks/relay_load.py
	$(BIN)/python benchmarks/ab_speed.py relay --base HEAD --ticks 150  # (the committed tree against the working one)
	$(BIN)/python benchmarks/fig_viewer.py

# the API reference from the docstrings: build/api/index.html (pdoc)
api: $(STAMP)
	$(BIN)/python docs/api.py build/api

# the whole comparison on the shared clips: report in bench-out/report.html (docs/benchmarks.md)
bench-suite: $(WARM)
	$(BIN)/mocodec bench ../shared/data --out bench-out

clean:
	rm -rf $(VENV) build src/*.egg-info .pytest_cache
	find src tests benchmarks -name __pycache__ -type d -prune -exec rm -rf {} +
