# rally3d: `make demo` and `make test` each create/refresh the virtual environment, then do their job.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.rally3d-installed
DEMO   ?= runs/demo
SAMPLE := datasets/sample/padel_sample

.PHONY: venv chromium demo test test-all sample bench clean help

help:
	@echo "make demo   - set up .venv and run rally3d on the embedded sample clip"
	@echo "make test   - set up .venv and run the test suite (without slow tests)"
	@echo "make test-all - also the slow tests"
	@echo "make sample - regenerate the embedded sample datasets/sample (bit for bit)"
	@echo "make bench  - run the benchmarks in bench/ (prints figures)"

# The venv is rebuilt only when the dependency list changes. torch is installed first, alone, so pip
# takes the local CPU wheel (a later resolution that admits newer torch would pull the CUDA build).
$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --disable-pip-version-check torch==2.13.0
	$(PIP) install -q --disable-pip-version-check -c constraints.txt -e '.[dev,onnx]'
	$(PIP) install -q --disable-pip-version-check --no-deps trackers==2.6.1
	$(PY) -m inference.players.movenet_fetch
	$(PY) -c "import torch, cv2; assert torch.__version__.startswith('2.13.0'), torch.__version__"
	@! $(PIP) show -q opencv-python torchvision 2>/dev/null || { echo "opencv-python or torchvision got installed; only opencv-python-headless is allowed"; exit 1; }
	touch $(STAMP)

venv: $(STAMP)

# The browser tests drive Debian's chromium through Playwright (never `playwright install`: no downloads).
CHROMIUM ?= /usr/bin/chromium
chromium:
	@test -x $(CHROMIUM) || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing Debian chromium for the browser tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null; \
	  else echo "The browser tests need Debian chromium at $(CHROMIUM): run 'sudo apt-get install chromium' (or set CHROMIUM=/path)"; exit 1; fi; }

test: venv chromium
	$(PY) -m pytest -m "not slow" -q --durations=15

test-all: venv chromium
	$(PY) -m pytest -q

# The main job on the embedded sample: the whole pipeline with the shipped weights (scored against the sample's
# ground truth), an export of the replay, then the 3D review served until Ctrl-C (SERVE=0: do not serve).
SERVE ?= 1
demo: venv
	rm -rf $(DEMO) && mkdir -p $(DEMO)
	$(VENV)/bin/rally3d infer $(SAMPLE) --out $(DEMO)/padel_sample
	$(VENV)/bin/rally3d review $(DEMO)/padel_sample --export $(DEMO)/review
	@if [ "$(SERVE)" = 1 ]; then $(VENV)/bin/rally3d review $(DEMO)/padel_sample; fi

sample: venv
	$(PY) -m synth.sample datasets/sample
	$(PY) -m synth.contact_sheet datasets/sample/contact_sheet.jpg $(SAMPLE) datasets/sample/tennis_sample

bench: venv
	for b in bench/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) runs .pytest_cache
