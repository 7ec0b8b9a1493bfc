# flexlink_ros: the two set-up commands are `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements-installed

.PHONY: venv install demo test bench report clean

venv: $(STAMP)

# The venv is (re)built whenever the pinned requirements change.
$(STAMP): requirements.txt requirements-test.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements-test.txt
	touch $(STAMP)

# Non-editable install: console scripts in $(VENV)/bin and config files in
# $(VENV)/share/flexlink_ros, where ament_index finds them (AMENT_PREFIX_PATH=$(VENV)).
# The compiled step is also built in place, for the tests and tools run from this tree.
# build/ is removed first: setuptools reuses it, and a module renamed or removed since the
# last build would otherwise be installed again.
install: venv
	rm -rf build
	$(PY) -m pip install -q --no-deps --force-reinstall .
	$(PY) setup.py -q build_ext --inplace

demo: install
	$(VENV)/bin/flexlink demo

# One BLAS thread: the suite is one process of many small solves on a 2-core machine.
test: install
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q test

bench: install
	$(VENV)/bin/python benchmarks/estimator_bench.py

report: install
	$(VENV)/bin/flexlink report --out out/report

clean:
	rm -rf build install log out demo_out *.egg-info flexlink_ros/core/estimation/*.so
