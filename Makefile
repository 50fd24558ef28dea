# One command to set up and run the demo, one to run the tests (see README.md).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo test test-vcan paper bench wheel clean

$(BIN)/keepout: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --progress-bar on --upgrade pip
	@echo "installing keepout and its dependencies (a minute or two on a fresh machine; pip shows each download)"
	$(BIN)/pip install --progress-bar on -e '.[dev,dask]'
	@echo "compiling the numba kernels now, so the first run starts flying at once (keepout warmup)"
	$(BIN)/keepout warmup
	touch $(BIN)/keepout

# Open MCT for `keepout ground web`, from the npm registry (pinned in ground/web/package-lock.json).
OPENMCT := ground/web/node_modules/openmct/dist/openmct.js
$(OPENMCT): ground/web/package.json ground/web/package-lock.json
	@command -v npm >/dev/null 2>&1 || { echo "make setup: npm is missing (Debian: apt-get install -y npm)" >&2; exit 1; }
	@echo "installing Open MCT for the web display (npm)"
	npm ci --prefix ground/web --no-audit --no-fund --progress=true --loglevel=http
	touch $@

setup: $(BIN)/keepout $(OPENMCT)

demo: setup
	$(BIN)/keepout sil run

test: setup
	$(BIN)/python -m pytest -q

# SocketCAN tests where vcan0 exists; on a host without CAN, VCAN_RUN names a command that runs its
# arguments in a guest that has vcan0 (CI passes its own).
VCAN_RUN ?=
test-vcan: setup
	KEEPOUT_REQUIRE_VCAN=1 $(VCAN_RUN) $(BIN)/python -m pytest -q -m socketcan

paper: setup
	$(BIN)/keepout paper --out docs/paper

# The wheel as users get it, with the compiled kernels of its own sources (gnc/_numba_cache.py): a first
# run on a machine with this CPU and Python loads them instead of compiling. build/ goes first: setuptools
# would otherwise pack files left there by an earlier build.
wheel: setup
	$(BIN)/keepout warmup --prune
	rm -rf build dist
	$(BIN)/python -m pip wheel --no-deps -w dist .

clean:
	rm -rf $(VENV) build dist *.egg-info ground/web/node_modules
