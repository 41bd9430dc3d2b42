# The two README commands: `make demo` and `make test`. Both set up .venv from the pinned
# requirements first (only when the requirements changed) and are safe to run again.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.requirements-installed

.PHONY: setup demo test package sample render bench-blender clean

setup: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else \
	  "Python 3.11 is required (Blender 4.5-5.0 and the bpy wheel use it); found " + sys.version.split()[0])'
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	touch $(STAMP)

demo: setup
	$(PY) tools/demo.py

test: setup
	$(PY) -m pytest

# Re-render the realistic sample with Cycles (slow: about 40 s a frame; never run by CI).
sample: setup
	$(PY) tools/render_sample.py --output samples/sequence --overwrite

# docs/result.jpg: the demo's curve rendered with Cycles over its photo (after make demo).
render: setup
	$(PY) tools/render_result.py

# The add-on's live preview and operators with real bpy (tables; see README).
bench-blender: setup
	$(PY) tools/bench_blender.py

package: setup
	$(PY) tools/package.py --output-dir dist

clean:
	rm -rf build dist .pytest_cache
