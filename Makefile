# The two README commands: `make demo` and `make test`. Both set up .venv from the pinned
# requirements first (only when the requirements changed) and are safe to run again.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.requirements-installed

.PHONY: setup demo test package sample sample-looks sample-hard render bench-blender clean

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

# Re-render the held-out look captures in samples/looks (family:seed:crossings; 20 views at
# 640x480 on one thread: about 6 min a capture on two shared cores; never run by CI).
LOOK_CAPTURES := pale:1000:2 neutral:1005:4 hard_light:1001:3 air:1002:3 clutter:1002:5 \
                 patterned:1000:6 same_hue:1002:4
sample-looks: setup
	@for spec in $(LOOK_CAPTURES); do set -- $$(echo $$spec | tr : ' '); \
	  $(PY) tools/render_sample.py --output samples/looks/$$1-$$2 --look $$1 --look-seed $$2 \
	    --seed $$2 --crossings $$3 --extent 0.42 --views 20 --size 640x480 --samples 16 \
	    --threads 1 --overwrite || exit 1; done

# Re-render the held-out hard layouts in samples/hard (seed:look; a heap of 12-20 crossings,
# each of 30 views at 960x720 framing part of it: about 11 min a capture on two cores; never
# run by CI; `python -m engine bench topology` reconstructs them).
HARD_CAPTURES := 1004:default 1005:hard_light
sample-hard: setup
	@for spec in $(HARD_CAPTURES); do set -- $$(echo $$spec | tr : ' '); \
	  $(PY) tools/render_sample.py --output samples/hard/hard-$$1 --layout hard --seed $$1 \
	    --look $$2 --look-seed $$1 --views 30 --size 960x720 --samples 16 --overwrite \
	    || exit 1; done

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
