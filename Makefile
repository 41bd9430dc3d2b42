# The two README commands: `make demo` and `make test`. Both set up .venv from the pinned
# requirements first (only when the requirements changed) and are safe to run again.
#
# Blender lines (README: Supported Blender versions): .venv is the newest Blender (bpy 5.3,
# Python 3.13, numpy 2); `make test-all` also runs the suite in .venv-5.2 (the LTS, Python
# 3.13) and .venv-4.5 (the LTS before it, Python 3.11, numpy 1.26), each from its own
# requirements-dev*.txt. PYTHON313 and PYTHON311 name the interpreters if they are not found.

comma := ,
# The first of python$(1), Debian's and pyenv's python$(1) that runs and is that version (a
# pyenv shim of a version not selected is found but does not run).
pythons_named = python$(1) /usr/bin/python$(1) \
  $(wildcard $(or $(PYENV_ROOT),$(HOME)/.pyenv)/versions/$(1)*/bin/python$(1))
find_python = $(firstword $(foreach p,$(call pythons_named,$(1)),$(shell $(p) -c \
  'import sys; sys.version_info[:2] == ($(subst .,$(comma),$(1))) and print(sys.executable)' \
  2>/dev/null)))
PYTHON313 ?= $(call find_python,3.13)
PYTHON311 ?= $(call find_python,3.11)
VENV   := .venv
PY     := $(VENV)/bin/python
COMMON := requirements.txt requirements-test.txt

.PHONY: setup setup-all demo test test-4.5 test-5.2 test-all package sample sample-looks \
        sample-hard render bench-blender clean

# A line's virtual environment: $(1) folder, $(2) requirements file, $(3) interpreter,
# $(4) its version. Made again when it holds another Python (an older checkout's .venv).
define line_venv
$(1)/.requirements-installed: $(COMMON) $(2)
	@test -n "$(3)" || { echo "Python $(4) is required for $(1) ($(2)) but was not found:" \
	  "install it (e.g. \`pyenv install $(4)\`) or pass PYTHON$(subst .,,$(4))=/path/to/python$(4)" >&2; exit 1; }
	@$(1)/bin/python -c 'import sys; sys.exit(sys.version_info[:2] != ($(subst .,$(comma) ,$(4))))' \
	  2>/dev/null || { rm -rf $(1) && $(3) -m venv $(1); }
	$(1)/bin/python -m pip install --quiet --disable-pip-version-check -r $(2)
	touch $$@
endef
$(eval $(call line_venv,$(VENV),requirements-dev.txt,$(PYTHON313),3.13))
$(eval $(call line_venv,.venv-5.2,requirements-dev-5.2.txt,$(PYTHON313),3.13))
$(eval $(call line_venv,.venv-4.5,requirements-dev-4.5.txt,$(PYTHON311),3.11))

setup: $(VENV)/.requirements-installed

setup-all: setup .venv-5.2/.requirements-installed .venv-4.5/.requirements-installed

demo: setup
	$(PY) tools/demo.py

# The suite runs on every core (pytest-xdist): each test file on one worker, so a file's
# module fixtures are made once; PYTEST_WORKERS=0 runs it in this process alone.
PYTEST_WORKERS ?= auto
PYTEST := -m pytest -n $(PYTEST_WORKERS) --dist loadfile

test: setup
	$(PY) $(PYTEST)

# The suite in the other Blender lines (the installer test through each one's own installer).
test-4.5: .venv-4.5/.requirements-installed
	.venv-4.5/bin/python $(PYTEST)

test-5.2: .venv-5.2/.requirements-installed
	.venv-5.2/bin/python $(PYTEST)

# Every line, the newest last: its run also checks that the sample reconstructs to the same
# points in the others (tests/test_blender_lines.py).
test-all: test-4.5 test-5.2 test

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
