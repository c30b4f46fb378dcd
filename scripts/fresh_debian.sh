#!/usr/bin/env bash
# The README's two commands on a fresh Debian, as root: debootstraps a minimal root of SUITE (bookworm = Debian 12,
# trixie = Debian 13; no Python, no node) under /var/cache/gs-ibl-fresh/SUITE, puts a clean copy of the committed
# checkout (git archive HEAD) at /root/gs-ibl in it, and runs `bash scripts/demo.sh` then `bash scripts/test.sh`
# there. Logs: build/fresh/SUITE/{demo,test}.log; prints each one's result and time (build/fresh/SUITE/summary.txt).
# The root is deleted afterwards (--keep leaves it, unmounted, until the next run). Slow (bpy is ~800 MB, then the
# whole suite): not run by CI, where scripts/check_requirements.sh checks requirements.txt's wheels instead.
#   scripts/fresh_debian.sh bookworm|trixie [--keep]
set -euo pipefail
suite=${1:-}; keep=${2:-}
case "$suite" in
  bookworm|trixie) ;;
  *) sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 2 ;;
esac
# the roots' helpers (make_root, in_root, unmount_root), on a directory of our own: never the matrix's roots
export GS_IBL_ROOTS=${GS_IBL_FRESH_ROOTS:-/var/cache/gs-ibl-fresh}
# shellcheck source=scripts/blender_roots.sh
source "$(dirname "$0")/blender_roots.sh"
r="$ROOTS/$suite"
logs="$REPO/build/fresh/$suite"
mkdir -p "$logs"
rm -f "$logs"/*.log "$logs/summary.txt"
$SUDO mkdir -p "$ROOTS"

done_root() {
  unmount_root "$r"
  if [ "$keep" != "--keep" ]; then $SUDO rm -rf "${r:?}"; fi
}
trap done_root EXIT
t0=$SECONDS
say() { echo "[fresh] $*" | tee -a "$logs/summary.txt"; }
say "$suite: $(date -u '+%Y-%m-%d %H:%M UTC'), HEAD $(git -C "$REPO" log -1 --format='%h %s' | cut -c1-80)"
[ -z "$(git -C "$REPO" status --porcelain --untracked-files=no)" ] \
  || say "note: the working tree has uncommitted changes; the root gets HEAD only"

unmount_root "$r"
$SUDO rm -rf "$r"
make_root "$suite" "$suite" "" > "$logs/root.log" 2>&1 || { tail "$logs/root.log" >&2; exit 1; }
$SUDO mkdir -p "$r/root/gs-ibl"
git -C "$REPO" archive HEAD | $SUDO tar -x -C "$r/root/gs-ibl"
say "root made in $((SECONDS - t0)) s (debootstrap --variant=minbase $suite)"

# The host reaches the registries through a proxy whose CA make_root copied into the root; node needs to be told.
EXTRA_ENV="NODE_EXTRA_CA_CERTS=/etc/ssl/certs/ca-certificates.crt"
rc=0
for step in demo test; do
  t=$SECONDS
  if in_root "$r" bash -c "cd /root/gs-ibl && bash scripts/$step.sh" > "$logs/$step.log" 2>&1; then
    res=ok
  else
    res="FAILED (exit $?)"; rc=1
  fi
  say "$step.sh: $res in $(( (SECONDS - t) / 60 )) min $(( (SECONDS - t) % 60 )) s"
done
grep -h -e '^\[setup\] WARNING' -e '^\[demo\] skipping' -e '^\[node_tools\].*skipped' "$logs"/*.log \
  | sort -u | sed 's/^/[fresh]   /' | tee -a "$logs/summary.txt" || true
summary=$(grep -E '^(=+ )?[0-9]+ (passed|failed|error)' "$logs/test.log" | tail -n 1 || true)
say "pytest: ${summary:-no summary line (see $logs/test.log)}"
grep '^FAILED' "$logs/test.log" | cut -d' ' -f2 | sed 's/^/[fresh]   /' | tee -a "$logs/summary.txt" || true
versions=$(in_root "$r" /root/gs-ibl/.venv/bin/python -c '
import sys, numpy
try:
    import bpy; b = "bpy " + bpy.app.version_string
except Exception as e:
    b = "no bpy (%s)" % type(e).__name__
print("Python %d.%d.%d," % sys.version_info[:3], b + ", numpy " + numpy.__version__)' 2>/dev/null | tail -n 1 || true)
say "venv: ${versions:-none}; node: $(in_root "$r" sh -c 'node --version 2>/dev/null || echo none')"
say "total $(( (SECONDS - t0) / 60 )) min $(( (SECONDS - t0) % 60 )) s; logs in ${logs#"$REPO"/}/"
exit $rc
