#!/usr/bin/env bash
# Real Blenders for the test matrix, made once per machine and cached (the recipes of NOTES-real-blender.md):
#   bpy42, bpy50  venvs on the machine's Python 3.11 holding nothing but the bpy module (4.2 LTS, 5.0) and what it
#                 pulls in: an extension tested there sees only what Blender itself ships
#   trixie        a Debian 13 root (Python 3.13) with a venv holding only bpy 5.3
#   sid           a Debian sid root with Debian's real Blender 5.2 binary (Python 3.14), Xvfb and ImageMagick
#
#   scripts/blender_roots.sh ensure NAME...   make what is missing (a stamp holds the recipe's hash: a changed
#                                             recipe remakes its entry; an interrupted one is made again)
#   scripts/blender_roots.sh ready NAME       exit status 0 when NAME is made (with the current recipe)
#   scripts/blender_roots.sh path NAME        where it is
#   scripts/blender_roots.sh remove NAME      unmount and delete it
#   scripts/blender_roots.sh chroot NAME CMD  run CMD inside a root with /proc, /dev, /sys mounted and this checkout
#                                             bound read-only at /src; the root's /tmp is `path NAME`/tmp here
# Cached under $GS_IBL_ROOTS (default /var/cache/gs-ibl); made from scratch: ~3 min per root, ~1 min per bpy venv.
# A root whose recipe changed but whose Debian suite did not is topped up in place (apt-get install), not remade.
set -euo pipefail
ROOTS=${GS_IBL_ROOTS:-/var/cache/gs-ibl}
MIRROR=${GS_IBL_DEBIAN_MIRROR:-http://deb.debian.org/debian}
REPO=$(cd "$(dirname "$0")/.." && pwd)
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
APT_OPTS=(-o Acquire::Check-Valid-Until=false -o Acquire::Check-Date=false -o APT::Install-Recommends=false)

BPY42=4.2.0
NUMPY42=1.26.4  # what Blender 4.2 LTS bundles; bpy 4.2.0 asks for any numpy, so pip would take 2.x
BPY50=5.0.1
BPY53=5.3.0
SID_PACKAGES="blender libegl1 xvfb xauth imagemagick python3-numpy python3-openimageio python3-cffi python3-attr \
python3-typing-extensions python3-requests mesa-vulkan-drivers libvulkan1 libgl1-mesa-dri unzip xdotool"
TRIXIE_PACKAGES="libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libxxf86vm1 libsm6 libgl1 libegl1 \
mesa-vulkan-drivers libvulkan1"
CATTRS=25.3.0  # Blender's extensions add-on imports cattrs, which Debian does not package

recipe() {  # what an entry is made from: its stamp
  case "$1" in
    bpy42) echo "venv bpy==$BPY42 numpy==$NUMPY42 v1" ;;
    bpy50) echo "venv bpy==$BPY50 v1" ;;
    trixie) echo "trixie $TRIXIE_PACKAGES bpy==$BPY53 v1" ;;
    sid) echo "sid $SID_PACKAGES cattrs==$CATTRS v1" ;;
    *) echo "unknown entry '$1' (bpy42, bpy50, trixie, sid)" >&2; exit 2 ;;
  esac
}

stamp_ok() { [ "$(cat "$ROOTS/$1.stamp" 2>/dev/null)" = "$(recipe "$1" | sha1sum | cut -d' ' -f1)" ]; }
write_stamp() { recipe "$1" | sha1sum | cut -d' ' -f1 > "$ROOTS/$1.stamp"; }

mount_root() {  # idempotent: several runs may share a root
  local r=$1
  mountpoint -q "$r/proc" || $SUDO mount -t proc proc "$r/proc"
  mountpoint -q "$r/dev" || $SUDO mount --bind /dev "$r/dev"
  mountpoint -q "$r/dev/pts" || $SUDO mount --bind /dev/pts "$r/dev/pts"
  mountpoint -q "$r/sys" || $SUDO mount --bind /sys "$r/sys"
  $SUDO mkdir -p "$r/src"
  mountpoint -q "$r/src" || { $SUDO mount --bind "$REPO" "$r/src" && $SUDO mount -o remount,bind,ro "$r/src"; }
}

in_root() {  # a clean environment: only what the root's own programs should see
  local r=$1; shift
  $SUDO env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 \
    DEBIAN_FRONTEND=noninteractive SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt \
    PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_DEFAULT_TIMEOUT=180 ${EXTRA_ENV:-} chroot "$r" "$@"
}

unmount_root() {  # every bind mount first: deleting a root must never reach /dev or the checkout through /src
  local r=$1 m
  for m in src sys dev/pts dev proc; do mountpoint -q "$r/$m" 2>/dev/null && $SUDO umount -l "$r/$m"; done
  if grep -q " $r/" /proc/mounts; then echo "[roots] still mounted under $r" >&2; exit 1; fi
}

make_root() {  # make_root NAME SUITE PACKAGES: a changed package list tops the root up, a new suite remakes it
  local name=$1 suite=$2 packages=$3 r="$ROOTS/$1"
  if [ "$(cat "$r/.gs-ibl-base" 2>/dev/null)" != "$suite" ]; then
    command -v debootstrap >/dev/null || { $SUDO apt-get update -qq; $SUDO apt-get install -y -qq debootstrap >/dev/null; }
    unmount_root "$r"
    $SUDO rm -rf "$r"
    echo "[roots] debootstrap $suite into $r"
    $SUDO debootstrap --variant=minbase --include=ca-certificates "$suite" "$r" "$MIRROR" >/dev/null
    # the host's extra CAs (a proxy's) let apt and pip inside the root reach the registries
    if ls /usr/local/share/ca-certificates/*.crt >/dev/null 2>&1; then
      $SUDO cp /usr/local/share/ca-certificates/*.crt "$r/usr/local/share/ca-certificates/"
      in_root "$r" update-ca-certificates >/dev/null 2>&1
    fi
    printf 'Acquire::Check-Valid-Until "false";\nAcquire::Check-Date "false";\nAPT::Install-Recommends "false";\n' \
      | $SUDO tee "$r/etc/apt/apt.conf.d/99gs-ibl" >/dev/null
    echo "$suite" | $SUDO tee "$r/.gs-ibl-base" >/dev/null
  else
    echo "[roots] topping up $r"  # a root in use by another run stays usable meanwhile
  fi
  mount_root "$r"
  in_root "$r" apt-get "${APT_OPTS[@]}" update -qq
  # shellcheck disable=SC2086
  in_root "$r" apt-get "${APT_OPTS[@]}" install -y -qq $packages >/dev/null
}

ensure_one() {
  local name=$1
  recipe "$name" >/dev/null
  if stamp_ok "$name"; then return 0; fi
  $SUDO mkdir -p "$ROOTS"
  rm -f "$ROOTS/$name.stamp"
  local t0=$SECONDS
  case "$name" in
    bpy42|bpy50)
      local v; v=$([ "$name" = bpy42 ] && echo $BPY42 || echo $BPY50)
      local py=${PYTHON311:-python3.11}
      command -v "$py" >/dev/null || { echo "[roots] $name needs Python 3.11 ($py)" >&2; exit 1; }
      rm -rf "$ROOTS/$name"
      echo "[roots] venv with bpy==$v only: $ROOTS/$name"
      "$py" -m venv "$ROOTS/$name"
      # shellcheck disable=SC2046
      "$ROOTS/$name/bin/python" -m pip install -q "bpy==$v" $([ "$name" = bpy42 ] && echo "numpy==$NUMPY42")
      ;;
    trixie)
      make_root trixie trixie "python3 python3-venv $TRIXIE_PACKAGES"
      in_root "$ROOTS/trixie" python3 -m venv /opt/bpy53
      in_root "$ROOTS/trixie" /opt/bpy53/bin/pip install -q "bpy==$BPY53"
      ;;
    sid)
      make_root sid sid "$SID_PACKAGES python3-pip"
      # cattrs: pure Python, unpacked where Debian's python3 finds it
      in_root "$ROOTS/sid" python3 -m pip download -q --no-deps --only-binary=:all: -d /tmp/cattrs "cattrs==$CATTRS"
      in_root "$ROOTS/sid" sh -c 'cd /usr/lib/python3/dist-packages && unzip -oq /tmp/cattrs/*.whl && rm -rf /tmp/cattrs'
      ;;
  esac
  write_stamp "$name"
  echo "[roots] $name ready in $((SECONDS - t0)) s"
}

main() {
  local cmd=${1:-} name r; shift || true
  case "$cmd" in
    ensure) for n in "$@"; do ensure_one "$n"; done ;;
    path) recipe "$1" >/dev/null; echo "$ROOTS/$1" ;;
    ready) stamp_ok "$1" ;;
    remove) recipe "$1" >/dev/null; rm -f "$ROOTS/$1.stamp"; unmount_root "$ROOTS/$1"; $SUDO rm -rf "${ROOTS:?}/$1" ;;
    chroot)
      name=$1; shift
      stamp_ok "$name" || { echo "[roots] $name is not made: scripts/blender_roots.sh ensure $name" >&2; exit 1; }
      r="$ROOTS/$name"
      mount_root "$r"
      in_root "$r" "$@"
      ;;
    *) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 2 ;;
  esac
}

# Sourced (scripts/fresh_debian.sh), it only defines the helpers above: make_root, in_root, unmount_root.
if [ "${BASH_SOURCE[0]}" = "$0" ]; then main "$@"; fi
