#!/usr/bin/env bash
# Runs tests/real_blender/final_frame_probe.py in each real Blender of scripts/blender_roots.sh (those made), for
# Cycles and EEVEE: build the scene, render `-f 1` (the binary's own flag; in the bpy module the same RE_RenderAnim
# path with frames 1..1), `-a` over frames 1..3 and an F12 still (write_still) at frame 2 (with Cycles also one
# cropped to a render border), then check every
# written frame with numpy + OpenImageIO in this checkout's .venv. Results: build/final-frame/<entry>/.
# blender-5.2-gui: Blender's window under Xvfb, Render Animation and Render Image started as a user does
# (INVOKE_DEFAULT: the render runs as a job beside the event loop), and Escape pressed (xdotool) during an animation.
#   tests/real_blender/final_frame_probe.sh [ENTRY...]   entries: bpy-4.2 bpy-5.0 bpy-5.3 blender-5.2 blender-5.2-gui
#                                                        (default all)
set -uo pipefail
REPO=$(cd "$(dirname "$0")/../.." && pwd)
ROOTS="bash $REPO/scripts/blender_roots.sh"
PROBE=tests/real_blender/final_frame_probe.py
OUT=$REPO/build/final-frame
ENGINES=${ENGINES:-"CYCLES EEVEE"}
entries=("$@"); [ ${#entries[@]} -eq 0 ] && entries=(bpy-4.2 bpy-5.0 bpy-5.3 blender-5.2 blender-5.2-gui)
status=0

for entry in "${entries[@]}"; do
  case $entry in
    bpy-4.2) root=bpy42 ;; bpy-5.0) root=bpy50 ;; bpy-5.3) root=trixie ;; blender-5.2|blender-5.2-gui) root=sid ;;
    *) echo "unknown entry $entry" >&2; exit 2 ;;
  esac
  $ROOTS ready $root || { echo "[final-frame] $entry: $root not made (scripts/blender_roots.sh ensure $root)"; continue; }
  rootdir=$($ROOTS path $root)
  case $root in
    bpy42|bpy50) inner=$OUT/$entry; host=$inner; probe=$REPO/$PROBE
                 run() { (cd "$host" && env -i PATH=/usr/bin:/bin HOME="$host" "$@"); }
                 py=$rootdir/bin/python ;;
    *) inner=/tmp/final-frame/$entry; host=$rootdir$inner; probe=/src/$PROBE
       run() { $ROOTS chroot $root env -C "$inner" HOME="$inner" "$@"; }
       py=/opt/bpy53/bin/python ;;
  esac
  rm -rf "$host" "$OUT/$entry"; mkdir -p "$host"
  tags=()
  for engine in $ENGINES; do
    e=${engine,,}
    blend=$inner/scene_$e.blend
    t0=$SECONDS
    if [ $entry = blender-5.2-gui ]; then
      for esc in "" --esc; do
        [ -n "$esc" ] && [ $engine != CYCLES ] && continue
        s=$SECONDS
        run sh -c 'rm -f display; Xvfb -displayfd 3 -screen 0 1280x800x24 -nolisten tcp 3>display 2>xvfb.log & x=$!; i=0
          while [ ! -s display ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done
          DISPLAY=:$(cat display) timeout 600 blender --python "$0" -- --job gui $1 --engine $2 --out "$3"; rc=$?; kill $x; exit $rc' \
          "$probe" "$esc" $engine "$inner" > "$host/${e}_gui$esc.log" 2>&1
        echo "${e}_gui$esc $((SECONDS - s)) s" >> "$host/times.txt"
      done
      tags+=("${e}_gui_anim:1-3" "${e}_gui_still:2")
      [ $engine = CYCLES ] && tags+=("${e}_gui_esc:1")
      echo "[final-frame] $entry $engine: $((SECONDS - t0)) s"
      continue
    elif [ $root = sid ]; then
      run blender -b --python "$probe" -- --job build --engine $engine --out "$inner" --blend "$blend" > "$host/build_$e.log" 2>&1
      s=$SECONDS; run blender -b "$blend" --python "$probe" -f 1 -- --job render --blend "$blend" --out "$inner" --tag ${e}_f1 --how none > "$host/${e}_f1.log" 2>&1; echo "${e}_f1 $((SECONDS - s)) s" >> "$host/times.txt"
      s=$SECONDS; run blender -b "$blend" --python "$probe" -a -- --job render --blend "$blend" --out "$inner" --tag ${e}_anim --how none > "$host/${e}_anim.log" 2>&1; echo "${e}_anim $((SECONDS - s)) s" >> "$host/times.txt"
      for how in still crop; do
        [ $how = crop ] && [ $engine != CYCLES ] && continue
        s=$SECONDS; run blender -b "$blend" --python "$probe" -- --job render --blend "$blend" --out "$inner" --tag ${e}_$how --how $how > "$host/${e}_$how.log" 2>&1; echo "${e}_$how $((SECONDS - s)) s" >> "$host/times.txt"
      done
    else
      run $py "$probe" --job build --engine $engine --out "$inner" --blend "$blend" > "$host/build_$e.log" 2>&1
      for how in f1 anim still crop; do
        [ $how = crop ] && [ $engine != CYCLES ] && continue
        s=$SECONDS
        run $py "$probe" --job render --blend "$blend" --out "$inner" --tag ${e}_$how --how $how > "$host/${e}_$how.log" 2>&1
        echo "${e}_$how $((SECONDS - s)) s" >> "$host/times.txt"
      done
    fi
    tags+=("${e}_f1:1" "${e}_anim:1-3" "${e}_still:2")
    [ $engine = CYCLES ] && tags+=("${e}_crop:2")
    echo "[final-frame] $entry $engine: $((SECONDS - t0)) s"
  done
  [ "$host" != "$OUT/$entry" ] && { mkdir -p "$OUT"; cp -r "$host" "$OUT/$entry"; rm -rf "$host"; }
  (IFS=,; "$REPO/.venv/bin/python" "$REPO/$PROBE" --job check --out "$OUT/$entry" --tags "${tags[*]}") \
    | tee "$OUT/$entry/check.txt" || status=1
done
exit $status
