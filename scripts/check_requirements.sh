#!/usr/bin/env bash
# A fast guard (run by .ci/run) that requirements.txt resolves to wheels only on both Pythons that get bpy:
# 3.11 (bpy 5.0.1; Debian 12, Ubuntu 22.04) and 3.13 (bpy 5.3.0; Debian 13), so that scripts/setup.sh never falls
# back to building a package from source there. scripts/fresh_debian.sh is the slow, whole check.
# pip resolves the file on a real interpreter of each version, since environment markers are evaluated on the
# running Python (not on --python-version): the machine's python3.11 ($PYTHON311), and the Debian 13 root of
# scripts/blender_roots.sh (made when missing). Nothing is installed or downloaded beyond metadata: bpy's wheel
# (~400 MB, no separate metadata on PyPI) is read by HTTP range requests (pip's fast-deps). About 1 min.
set -euo pipefail
cd "$(dirname "$0")/.."
PIP_ARGS=(-m pip install --dry-run --ignore-installed --only-binary :all: --use-feature=fast-deps -q --report -)
summarise() {  # the report on stdin: one line naming what would be installed
  python3 -c '
import json, sys
d = json.load(sys.stdin)
pins = {i["metadata"]["name"].lower(): i["metadata"]["version"] for i in d["install"]}
key = ", ".join("%s %s" % (n, pins[n]) for n in ("bpy", "numpy") if n in pins)
print("wheels only, %d packages (%s)" % (len(pins), key or "no bpy"))'
}
check() {  # check LABEL REQ CMD...: CMD runs the Python whose pip resolves requirements.txt (at REQ there)
  local label=$1 req=$2 out line err; shift 2
  err=$(mktemp)
  if out=$("$@" "${PIP_ARGS[@]}" -r "$req" 2>"$err") && line=$(summarise <<<"$out" 2>>"$err"); then
    echo "[requirements] Python $label: $line"; rm -f "$err"
  else
    echo "[requirements] Python $label: requirements.txt does not resolve to wheels only:" >&2
    grep -v -e 'is ignored: it is neither' -e 'fast-deps' "$err" | tail -n 15 >&2; rm -f "$err"
    return 1
  fi
}

bash scripts/blender_roots.sh ready trixie || bash scripts/blender_roots.sh ensure trixie
py311=${PYTHON311:-python3.11}
# the two side by side (each mostly waits on PyPI); the root sees this checkout at /src, and its bpy venv's pip
# resolves there (the root's python3 is Debian's, without pip)
check "3.11 ($py311)" requirements.txt "$py311" & p311=$!
check "3.13 (the Debian 13 root)" /src/requirements.txt \
  bash scripts/blender_roots.sh chroot trixie /opt/bpy53/bin/python & p313=$!
rc=0
wait $p311 || rc=1
wait $p313 || rc=1
exit $rc
