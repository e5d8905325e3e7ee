#!/usr/bin/env bash
# Install viewdb and everything it needs on a fresh Debian/Python 3.11 machine:
# the system libraries for headless rendering (Mesa's EGL, software rasteriser) and the
# headless browser the web page's tests use (chromium, chromium-driver), then the package
# itself in editable mode with its dev extra, which brings every other extra (ingest,
# serve, bench, ray). Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"

need_apt=()
for lib in libEGL.so.1 libEGL_mesa.so.0 libGL.so.1; do
  if ! ldconfig -p 2>/dev/null | grep -q "$lib"; then need_apt=(libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libglib2.0-0); break; fi
done
# the web page's tests drive Debian's headless Chromium through its chromedriver (never a
# downloaded browser)
[ -x /usr/bin/chromium ] || need_apt+=(chromium)
[ -x /usr/bin/chromedriver ] || need_apt+=(chromium-driver)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "install.sh: installing system packages: ${need_apt[*]}"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}"
fi

PYTHON="${PYTHON:-python3}"
"$PYTHON" -m pip install --quiet --disable-pip-version-check -e ".[dev]"
command -v pyenv >/dev/null 2>&1 && pyenv rehash || true

# Fail here, not at a user's desk, if headless rendering does not work.
"$PYTHON" - <<'PY'
import viewdb.catalogue.gl
viewdb.catalogue.gl.pyrender_module()
from viewdb.catalogue.render import get_renderer
get_renderer()
print("install.sh: viewdb installed; headless rendering works")
PY

# Compile the search kernels now (numba caches them on disk), not during a user's first
# query: a throw-away catalogue is ingested and queried with every plan (viewdb/warm.py).
"$PYTHON" - <<'PY'
from viewdb.warm import warm_up
report = warm_up()
print(f"install.sh: search kernels ready ({report.compiled} compiled, {report.cached} from the cache)")
PY
