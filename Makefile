# Two commands do all set-up on a fresh Debian/Ubuntu machine:
#   make run   - install and open the viewer (or render glassray.png without a display)
#   make test  - install with test extras and system libraries, then run pytest
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
APT_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 xvfb xdotool
# Wanted, not needed: libLLVM >= 16 lets the physically based peer (Mitsuba 3,
# viewer/peer.py) run its fast llvm_ad_rgb variant instead of scalar_rgb;
# glslangValidator (glslang-tools) lets tests/test_glsl_portability.py check
# every shader program against the GLSL spec (skipped without it).
OPTIONAL_APT := libllvm19 glslang-tools
# Debian 12's Mesa (22.3) runs both sides of every branch on llvmpipe; Mesa 25
# from bookworm-backports skips a branch that no pixel of a SIMD group takes,
# and draws the default frame 2-3x faster (docs/performance.md).  As root on
# Debian 12, system-deps takes these from bookworm-backports (adding that suite
# to apt's sources if it is not there); GLASSRAY_DISTRO_MESA=1 keeps Debian's.
# Without root it only says how.  glassray works with either.
MESA_BACKPORT := libegl-mesa0 libgl1-mesa-dri libosmesa6 libglx-mesa0 libgbm1
BACKPORTS_LIST := /etc/apt/sources.list.d/glassray-bookworm-backports.sources

.PHONY: run test system-deps venv clean

# Install Mesa (EGL + OSMesa), Xvfb and xdotool when any is missing and we can,
# and python3-venv when $(PYTHON) cannot make the virtual environment (Debian's
# python3 has no ensurepip without it).
system-deps:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ ! -x $(PY) ] && ! $(PYTHON) -c "import ensurepip, venv" >/dev/null 2>&1; then \
	  missing="$$missing python3-venv"; fi; \
	if [ -n "$$missing" ]; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing system packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  elif command -v sudo >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then \
	    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else echo "warning: missing system packages:$$missing (install them with your package manager)"; fi; \
	fi; \
	for p in $(OPTIONAL_APT); do dpkg -s $$p >/dev/null 2>&1 && continue; \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$p >/dev/null 2>&1 \
	      || { apt-get update -qq >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$p >/dev/null 2>&1; }; } \
	      || echo "note: optional package $$p not installed (see OPTIONAL_APT in the Makefile)"; fi; \
	done; \
	mesa=$$(dpkg-query -W -f='$${Version}' libegl-mesa0 2>/dev/null); \
	if [ -z "$$GLASSRAY_DISTRO_MESA" ] && [ -n "$$mesa" ] && grep -qs '^VERSION_CODENAME=bookworm' /etc/os-release \
	   && dpkg --compare-versions "$$mesa" lt 25; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "Mesa $$mesa runs every branch on llvmpipe: installing Mesa from bookworm-backports (GLASSRAY_DISTRO_MESA=1 keeps it)"; \
	    grep -rqs 'bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d \
	      || printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
	           "$$(sed -n 's/^URIs: *\([^ ]*\/debian\)$$/\1/p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | head -n1 | grep . || echo http://deb.debian.org/debian)" \
	           > $(BACKPORTS_LIST); \
	    { apt-get update -qq >/dev/null 2>&1 \
	      && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq -t bookworm-backports $(MESA_BACKPORT) >/dev/null 2>&1; } \
	      || echo "note: Mesa from bookworm-backports not installed; keeping Mesa $$mesa"; \
	  else echo "note: Mesa $$mesa runs every branch on llvmpipe; Mesa 25 from bookworm-backports draws 2-3x faster (see the README)"; fi; \
	fi

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install -q --upgrade 'setuptools>=77' wheel   # the build-system's, for the offline wheel test
	$(PY) -m pip install -q -e '.[test]'
	@touch $@

venv: $(STAMP)

run: system-deps $(STAMP)
	@if [ -n "$$DISPLAY$$WAYLAND_DISPLAY" ] && $(VENV)/bin/glassray view --probe >/dev/null 2>&1; then \
	  $(VENV)/bin/glassray; \
	else \
	  echo "no display (or no viewer): rendering the default scene offscreen instead"; \
	  $(VENV)/bin/glassray render -o glassray.png && echo "wrote $$(pwd)/glassray.png"; \
	fi

test: system-deps $(STAMP)
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
