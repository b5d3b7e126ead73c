#!/usr/bin/env bash
# Set up virtus on Debian/Ubuntu: the system libraries it needs, then a virtual environment
# `.venv` at the repository root with virtus (editable) and its test tools.
# Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# Mitsuba's CPU backend (llvm_ad_rgb) needs a libLLVM >= 16 shared library; LLVM 15 crashes.
LLVM_CANDIDATES=(libllvm19 libllvm18 libllvm17 libllvm16)

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
        echo "bootstrap: need root (or sudo) to run: $*" >&2; return 1; fi
}

have_llvm() {
    local pkg
    for pkg in "${LLVM_CANDIDATES[@]}"; do
        dpkg -s "$pkg" >/dev/null 2>&1 && return 0
    done
    return 1
}

if command -v apt-get >/dev/null; then
    missing=()
    python3 -c "import venv, ensurepip" >/dev/null 2>&1 || missing+=(python3-venv python3-pip)
    command -v python3 >/dev/null || missing+=(python3)
    # tests/report/test_browser.py: a real headless browser and its WebDriver (Debian's).
    command -v chromium >/dev/null || missing+=(chromium)
    command -v chromedriver >/dev/null || missing+=(chromium-driver)
    if [ ${#missing[@]} -gt 0 ] || ! have_llvm; then
        export DEBIAN_FRONTEND=noninteractive
        as_root apt-get update -qq
        if ! have_llvm; then
            for pkg in "${LLVM_CANDIDATES[@]}"; do
                if apt-cache show "$pkg" >/dev/null 2>&1; then missing+=("$pkg"); break; fi
            done
        fi
        if [ ${#missing[@]} -gt 0 ]; then
            as_root apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
        fi
    fi
    have_llvm || echo "bootstrap: warning: no libLLVM >= 16 found; the CPU renderer will not run" >&2
else
    echo "bootstrap: no apt-get: install python3 (>= 3.11, with venv) and libLLVM >= 16 yourself" >&2
fi

if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[dev]"
echo "bootstrap: ready ($(.venv/bin/python -c 'import virtus; print("virtus", virtus.__version__)'))"
