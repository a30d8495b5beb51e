# Set-up on a fresh Debian/Ubuntu machine.  `make run` and `make test` install
# what is missing from the apt sources the machine already has (as root, or
# through sudo); neither adds an apt source nor replaces a system library.
#   make run       - Mesa's EGL and OSMesa (and python3-venv when python3 needs
#                    it), .venv with glassray[bench]; then open the viewer, or
#                    without a display render glassray.png
#   make test      - that, Xvfb, xdotool (libllvm19 and glslang-tools when it
#                    can) and .venv with glassray[test]; then run pytest
#                    (PYTEST_ARGS='-x -k bench' passes options to it)
#   make fast-mesa - Debian 12 only: Mesa 25 from bookworm-backports, 2-3x
#                    faster (adds that apt source; says what it will do and
#                    how to undo it first)
#   make venv      - only .venv, with the test extras; make clean removes it
# PYTHON=python3.12 picks another Python (3.11 or newer), VENV=dir another venv.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP_RUN  := $(VENV)/.installed-run
STAMP_TEST := $(VENV)/.installed-test
PYTEST_ARGS ?=
RUN_APT  := libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6
TEST_APT := xvfb xdotool
# Wanted by the tests, not needed: libLLVM >= 16 lets the physically based peer
# (Mitsuba 3, viewer/measure/peer.py) run its fast llvm_ad_rgb variant instead of
# scalar_rgb; glslangValidator (glslang-tools) lets
# tests/gpu/test_glsl_portability.py check every shader program against the GLSL
# spec (skipped without it).  Installed only as root.
OPTIONAL_APT := libllvm19 glslang-tools
# Debian 12's Mesa (22.3) runs both sides of every branch on llvmpipe; Mesa 25
# from bookworm-backports skips a branch that no pixel of a SIMD group takes,
# and draws the default frame 2-3x faster (docs/performance.md).  Only
# `make fast-mesa` installs it (.ci/run calls it); `make run` and `make test`
# name it in one line where it would help (not with GLASSRAY_DISTRO_MESA=1,
# which also makes fast-mesa keep Debian's).  glassray works with either.
MESA_BACKPORT := libegl-mesa0 libgl1-mesa-dri libosmesa6 libglx-mesa0 libgbm1
BACKPORTS_LIST := /etc/apt/sources.list.d/glassray-bookworm-backports.sources
# The installed Mesa (libegl-mesa0's Debian version; empty when there is none).
MESA_VERSION = $(shell dpkg-query -W -f='$${Status} $${Version}\n' libegl-mesa0 2>/dev/null | sed -n 's/^install ok installed //p' | head -n1)

.PHONY: run test fast-mesa system-deps run-deps test-deps venv clean

# $(call apt_need,PACKAGES,WHAT): install those of PACKAGES that dpkg lacks,
# with apt-get as root or through sudo, else warn.  $$missing may be preset.
apt_need = for p in $(1); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing system packages for $(2):$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  elif command -v sudo >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing system packages for $(2) (sudo):$$missing"; \
	    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else echo "warning: missing system packages:$$missing (install them with your package manager)"; fi; \
	fi

# One line naming fast-mesa, on Debian 12 with Mesa < 25.
mesa_note = mesa='$(MESA_VERSION)'; \
	if [ -z "$$GLASSRAY_DISTRO_MESA" ] && [ -n "$$mesa" ] && grep -qs '^VERSION_CODENAME=bookworm' /etc/os-release \
	   && dpkg --compare-versions "$$mesa" lt 25; then \
	  echo "note: Mesa $${mesa%%-*} runs every branch on llvmpipe; 'make fast-mesa' installs Mesa 25 from bookworm-backports (2-3x faster)"; fi

# What running needs: Mesa's EGL and OSMesa, and python3-venv when $(PYTHON)
# cannot make the virtual environment (Debian's python3 has no ensurepip
# without it).
run-deps:
	@missing=""; \
	if [ ! -x $(PY) ] && ! $(PYTHON) -c "import ensurepip, venv" >/dev/null 2>&1; then \
	  missing=" python3-venv"; fi; \
	$(call apt_need,$(RUN_APT),run)

# What the tests need on top (Xvfb, xdotool), and as root the wanted ones.
test-deps: run-deps
	@missing=""; $(call apt_need,$(TEST_APT),test); \
	for p in $(OPTIONAL_APT); do dpkg -s $$p >/dev/null 2>&1 && continue; \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$p >/dev/null 2>&1 \
	      || { apt-get update -qq >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$p >/dev/null 2>&1; }; } \
	      || echo "note: optional package $$p not installed (see OPTIONAL_APT in the Makefile)"; fi; \
	done

system-deps: run-deps test-deps

# Mesa 25 from bookworm-backports on Debian 12 with an older Mesa: says what it
# will do, then adds the suite to apt's sources (unless it is there) and
# upgrades $(MESA_BACKPORT) from it.  Exits 0 when there is nothing to do.
fast-mesa:
	@mesa='$(MESA_VERSION)'; \
	if ! grep -qs '^VERSION_CODENAME=bookworm' /etc/os-release || ! command -v apt-get >/dev/null 2>&1; then \
	  echo "fast-mesa: nothing to do: this is not Debian 12 (bookworm), whose Mesa 22.3 it replaces"; exit 0; fi; \
	if [ -n "$$mesa" ] && dpkg --compare-versions "$$mesa" ge 25; then \
	  echo "fast-mesa: nothing to do: Mesa $$mesa is installed"; exit 0; fi; \
	if [ -n "$$GLASSRAY_DISTRO_MESA" ]; then \
	  echo "fast-mesa: nothing to do: GLASSRAY_DISTRO_MESA is set, keeping Debian's Mesa $$mesa"; exit 0; fi; \
	mirror=$$(sed -n 's/^URIs: *\([^ ]*\/debian\)$$/\1/p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | head -n1 | grep . || echo http://deb.debian.org/debian); \
	src=$(BACKPORTS_LIST); \
	if grep -rqs '^[^#]*bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d; then src=""; fi; \
	echo "fast-mesa: Mesa $${mesa:-(none)} runs every branch on llvmpipe; Mesa 25 from bookworm-backports draws 2-3x faster. This will:"; \
	if [ -n "$$src" ]; then \
	  echo "  add the apt source $$src (bookworm-backports main from $$mirror; apt still takes nothing else from it unless asked)"; \
	else echo "  use the bookworm-backports source apt already has"; fi; \
	echo "  apt-get update, then apt-get install -t bookworm-backports $(MESA_BACKPORT)"; \
	echo "  (upgrading those and the Mesa and libdrm packages they need to the backports' versions)"; \
	echo "  to undo: $${src:+rm $$src; }apt-get update; apt-get install --allow-downgrades PACKAGE/bookworm for each PACKAGE it lists at the end"; \
	if [ "$$(id -u)" != 0 ]; then \
	  echo "fast-mesa: needs root: run 'sudo make fast-mesa' (or make fast-mesa as root)"; exit 1; fi; \
	before=$$(dpkg-query -W -f='$${Package} $${Version}\n' | grep '~bpo12' || true); \
	if [ -n "$$src" ]; then \
	  printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' "$$mirror" > $$src; fi; \
	if ! { apt-get update -qq >/dev/null \
	       && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq -t bookworm-backports $(MESA_BACKPORT) >/dev/null; }; then \
	  if [ -n "$$src" ]; then rm -f $$src; echo "fast-mesa: removed $$src again"; fi; \
	  echo "fast-mesa: failed (is bookworm-backports reachable?); keeping Mesa $${mesa:-(none)}"; exit 1; fi; \
	now=$$(dpkg-query -W -f='$${Package} $${Version}\n' | grep '~bpo12' || true); \
	changed=$$(printf '%s\n' "$$now" | grep -vxF -e "$$before" | cut -d' ' -f1 | tr '\n' ' '); \
	echo "fast-mesa: Mesa $$(dpkg-query -W -f='$${Version}' libegl-mesa0 2>/dev/null) installed; from bookworm-backports now: $${changed:-nothing new}"; \
	echo "  to undo: $${src:+rm $$src; }apt-get update; apt-get install --allow-downgrades $$(for p in $$changed; do printf '%s/bookworm ' $$p; done)"

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

# Running: the runtime dependencies and the bench plot's extra (matplotlib).
$(STAMP_RUN): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e '.[bench]'
	@touch $@

# Testing: the test extra, which takes in bench's and peer's (so this stamp
# stands for run's too), and the build-system's setuptools and wheel for the
# offline wheel test (tests/test_packaging.py).
$(STAMP_TEST): pyproject.toml | $(PY)
	$(PY) -m pip install -q --upgrade 'setuptools>=77' wheel
	$(PY) -m pip install -q -e '.[test]'
	@touch $@ $(STAMP_RUN)

venv: $(STAMP_TEST)

run: run-deps $(STAMP_RUN)
	@$(mesa_note)
	@if [ -n "$$DISPLAY$$WAYLAND_DISPLAY" ] && $(VENV)/bin/glassray view --probe >/dev/null 2>&1; then \
	  $(VENV)/bin/glassray; \
	else \
	  echo "no display (or no viewer): rendering the default scene offscreen instead"; \
	  $(VENV)/bin/glassray render -o glassray.png && echo "wrote $$(pwd)/glassray.png"; \
	fi

test: test-deps $(STAMP_TEST)
	@$(mesa_note)
	$(PY) -m pytest -q $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
