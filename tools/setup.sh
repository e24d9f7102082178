#!/usr/bin/env bash
# Idempotent setup: a virtual environment in .venv with motion and its dependencies, and
# Debian's libllvm19 only when drjit's LLVM backend cannot render with what is installed.
# Prints what it does; safe to run again (it then installs nothing new).
set -euo pipefail
cd "$(dirname "$0")/.."
say() { printf '[setup] %s\n' "$*"; }

PY=${PYTHON:-python3}
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  say "need Python >= 3.11 (found: $("$PY" --version 2>&1))"; exit 1
fi

if [ ! -x .venv/bin/python ]; then
  say "creating virtual environment .venv ($("$PY" --version))"
  "$PY" -m venv .venv
fi

stamp=.venv/.motion-install-stamp
want=$(cat pyproject.toml setup.py | sha256sum | cut -c1-16)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  say "installing motion and its dependencies into .venv (pip)"
  .venv/bin/python -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
  # pip's output goes to a log, shown only if the install fails
  if ! .venv/bin/python -m pip install --quiet -e '.[dev]' > .venv/pip-install.log 2>&1; then
    cat .venv/pip-install.log; say "installation failed (pip's output above, also in .venv/pip-install.log)"; exit 1
  fi
  .venv/bin/python -c 'import motion.pipeline, mitsuba, drjit, OpenEXR, av, distributed' \
    || { say "installation incomplete: a package does not import (see .venv/pip-install.log)"; exit 1; }
  echo "$want" > "$stamp"
else
  say "python packages up to date"
fi

if .venv/bin/python -m motion.pipeline.variant --check-llvm >/tmp/motion-llvm-check.$$ 2>&1; then
  say "$(cat /tmp/motion-llvm-check.$$)"
else
  say "drjit's LLVM backend cannot render with the installed libLLVM; installing Debian's libllvm19"
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
  if .venv/bin/python -m motion.pipeline.variant --check-llvm >/tmp/motion-llvm-check.$$ 2>&1; then
    say "$(cat /tmp/motion-llvm-check.$$)"
  else
    say "warning: still no working libLLVM; motion will fall back to the slow scalar renderer"
  fi
fi
rm -f /tmp/motion-llvm-check.$$

# `--test` (make test, CI): what the suite needs beyond motion itself, so that no test skips
# for a tool CI could have: headless Chromium (the flipbook's and compare report's pages run in
# it) and the Khronos glTF validator (npm). Each only when missing.
if [ "${1:-}" = "--test" ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1; then
    say "installing Debian's chromium (headless pages in the tests)"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null \
      || say "warning: chromium did not install; the page tests will skip"
  fi
  if [ ! -f .node/node_modules/gltf-validator/index.js ]; then
    if ! command -v npm >/dev/null 2>&1; then
      $SUDO apt-get update -qq
      DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq npm >/dev/null || true
    fi
    say "installing the Khronos glTF validator into .node/ (npm)"
    npm install --silent --no-audit --no-fund --prefix .node gltf-validator >/dev/null 2>&1 \
      || say "warning: gltf-validator did not install; its test will skip"
  fi
fi
# bytecode for motion's own modules: where PYTHONDONTWRITEBYTECODE is set (CI images often
# do) every `motion` command would otherwise compile them from source (~0.1 s a process)
.venv/bin/python -m compileall -q -j0 pipeline cli configs >/dev/null 2>&1 || true
say "ready: .venv/bin/motion (or 'source .venv/bin/activate' and then 'motion')"
