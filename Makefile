# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-kernels venv bench embedded clean generated docs

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test,modelica,files,docs]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/duffid demo --out out

# the suite on every core (pytest-xdist; each test is independent: its files in tmp_path, the
# compiled libraries cached under content hashes and renamed into place)
test: $(STAMP)
	$(BIN)/python -m pytest -n auto

# the documentation site, docs/_build/html/index.html, with the paper report (duffid paper-report)
# at docs/_build/html/paper-report/; CI builds it with SPHINXOPTS="-W --keep-going" (warnings fail)
SPHINXOPTS ?=
docs: $(STAMP)
	$(BIN)/duffid paper-report -o docs/_build/extra/paper-report
	$(BIN)/sphinx-build -b html $(SPHINXOPTS) docs docs/_build/html

# the numerically sensitive tests under every OpenBLAS kernel and thread count (a table)
test-kernels: $(STAMP)
	$(BIN)/python benchmarks/kernels.py --calibrate

bench: $(STAMP)
	$(BIN)/python benchmarks/identification.py
	$(BIN)/python benchmarks/nonlinearity.py --out out
	$(BIN)/python benchmarks/silverbox.py
	$(BIN)/python benchmarks/cosim.py
	$(BIN)/python benchmarks/trust.py
	$(BIN)/python benchmarks/speed.py
	$(BIN)/python benchmarks/tracking.py
	$(BIN)/python benchmarks/motion_online.py
	$(BIN)/python benchmarks/platforms.py
	$(BIN)/python benchmarks/equations.py
	$(BIN)/python benchmarks/campaign.py
	$(BIN)/python benchmarks/embedded.py

# the C core on a Cortex-M4F under QEMU (instructions per update, flash, RAM, ARM = x86) and its
# x86 time per sample against a QR-RLS floor (needs gcc-arm-none-eabi, libnewlib-arm-none-eabi,
# qemu-system-arm); then the float build against the double build on benchmarks/trust.py's
# records (host compiler only; the simulated records are cached in build/trust_records)
embedded: $(STAMP)
	$(BIN)/python benchmarks/embedded.py

# files generated from one source: the C tables of the estimator options, the estimator core's
# facts (limits, return codes, statuses) and the controller parameters, from
# duffid.identification.options, duffid.identification.c_facts and duffid.control.settings
generated: $(STAMP)
	$(BIN)/python -c 'from duffid.identification.options import c_header; print(c_header(), end="")' \
		> fmus/estimator/duffid_options.h
	$(BIN)/python -c 'from duffid.identification.c_facts import c_header; print(c_header(), end="")' \
		> fmus/estimator/duffid_facts.h
	$(BIN)/python -c 'from duffid.control.settings import c_header; print(c_header(), end="")' \
		> fmus/controller/duffid_ctrl_params.h

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info
