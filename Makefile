# Two commands matter: `make serve` (set up and run the platform) and `make test`.
# Both build .venv from nothing; torch is installed first and pinned, so pip never
# pulls a multi-gigabyte CUDA build onto a machine that has none.

PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
TORCH  ?= torch==2.13.0
STAMP  := $(VENV)/.installed

.PHONY: setup kernels serve test test-fast lint format bench browser clean

# (setuptools' notice on every editable install is not for the people who run make serve)
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "$(TORCH)"
	PYTHONWARNINGS="ignore:Editable installation" $(PY) -m pip install --quiet -e ".[dev,ray,postgres,sb3]"
	touch $@

setup: $(STAMP) kernels

# The learner's compiled convolutions (learner/conv_kernel.py), one shared library per
# instruction set and source, each with explicit flags (never -march=native: the library must run on
# any CPU with those flags, and the learner picks by /proc/cpuinfo). Plain C loaded with
# ctypes, so no torch headers; where the compiler or the flags are missing the learner
# keeps its PyTorch update.
CC        ?= cc
KERNELS   := learner/kernels
KFLAGS    := -O3 -fPIC -shared -std=c11 -Wall -Wextra
kernels: $(KERNELS)/build/libconv1_avx512bf16.so $(KERNELS)/build/libconv1_avx2.so \
         $(KERNELS)/build/libconv23_avx512bf16.so $(KERNELS)/build/libconv23_avx2.so

$(KERNELS)/build/libconv1_avx512bf16.so: $(KERNELS)/conv1_bf16.c $(KERNELS)/conv1.h
	mkdir -p $(@D)
	$(CC) $(KFLAGS) -mavx512f -mavx512bw -mavx512vl -mavx512vbmi -mavx512bf16 -mfma -o $@ $< \
	  || echo "the AVX-512 BF16 kernel did not build: the learner uses PyTorch there"

$(KERNELS)/build/libconv1_avx2.so: $(KERNELS)/conv1_fp32.c $(KERNELS)/conv1.h
	mkdir -p $(@D)
	$(CC) $(KFLAGS) -mavx2 -mfma -o $@ $< \
	  || echo "the AVX2 kernel did not build: the learner uses PyTorch there"

# the second and third layers: one source, bfloat16 activations with -DCONV_BF16 (GCC's
# vector extensions, so the FMAs contract: -ffp-contract=fast)
$(KERNELS)/build/libconv23_avx512bf16.so: $(KERNELS)/conv23.c $(KERNELS)/conv23.h
	mkdir -p $(@D)
	$(CC) $(KFLAGS) -Wno-psabi -ffp-contract=fast -DCONV_BF16 -mavx512f -mavx512bw -mavx512vl \
	  -mavx512bf16 -mfma -o $@ $< \
	  || echo "the AVX-512 BF16 kernels did not build: the learner uses PyTorch there"

$(KERNELS)/build/libconv23_avx2.so: $(KERNELS)/conv23.c $(KERNELS)/conv23.h
	mkdir -p $(@D)
	$(CC) $(KFLAGS) -Wno-psabi -ffp-contract=fast -mavx2 -mfma -o $@ $< \
	  || echo "the AVX2 kernels did not build: the learner uses PyTorch there"

# Debian's Chromium drives the browser tests, through Debian's nginx in front of the
# server as deployed; installed when missing and we may.
browser:
	@{ command -v chromium && { command -v nginx || test -x /usr/sbin/nginx; }; } >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium nginx >/dev/null; \
	  else echo "chromium or nginx not found: browser tests will be skipped (apt-get install chromium nginx)"; fi; }

serve: setup
	$(VENV)/bin/ideeprl serve

# The suite's modules run in WORKERS processes (pytest-xdist; a module's tests stay together,
# each process starts its own live server), then the browser and proxy tests (tests/e2e) one
# at a time, as a participant's machine would run them: beside another test's learning run
# their software-rendered 3-D view lost its frame rate. test-fast is the inner loop between
# edits: no browser, no live server, no learning run.
WORKERS ?= 2

test: setup browser
	$(PY) -m pytest -n $(WORKERS) --dist loadfile --ignore=tests/e2e
	$(PY) -m pytest tests/e2e

test-fast: setup
	$(PY) -m pytest -n $(WORKERS) --dist loadfile -q -m "not slow and not browser and not live"

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports --no-cache
	$(PY) -m tests.mypy_baseline

format: setup
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

bench: setup
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache
