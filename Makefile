# Two-command quick start: `make demo` and `make test` both set themselves up from a clean clone.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test install bench lint clean browser

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (need Python >= 3.11)"; exit 2; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml setup.py
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/mmexec demo

test: $(STAMP) browser
	$(PY) -m pytest -q -m "not hardware" tests

# Debian's Chromium and ChromeDriver for the console's browser test
# (tests/serve/test_console_browser.py, driven by Playwright; no browser download).
# Without root or apt-get it says so and the test skips, except under CI=true, where it fails.
browser:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver) \
	      || echo "make browser: apt-get could not install chromium: the browser test will be skipped"; \
	  else \
	    echo "make browser: chromium is missing; install it as root: apt-get install chromium chromium-driver"; \
	  fi; }

bench: $(STAMP)
	for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

lint: $(STAMP)
	$(PY) -m ruff check executive drivers skills sim config tests benchmarks

clean:
	rm -rf $(VENV) build *.egg-info out
