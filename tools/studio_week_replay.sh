#!/usr/bin/env bash
# Replay issue 38 ("A studio's week") command by command in a scratch folder: versioned deliverables
# and partial reruns, per-frame invalidation, a shot's identity, keys and frames outside the timeline,
# small things. Usage: bash tools/studio_week_replay.sh CLONE   (a checkout whose .venv is set up)
set -u
clone=$1; M="$clone/.venv/bin/motion"; w=$(mktemp -d /tmp/replay38.XXXX); cd "$w"
say() { echo; echo "\$ $*"; "$@" 2>&1 | tail -n ${TAILN:-8}; echo "[exit ${PIPESTATUS[0]}]"; }
shot() {  # shot FILE NAME LASTKEY [FIRST]
cat > "$1" <<YAML
name: $2
timeline: {fps: 24, first: ${4:-0}, last: $(( ${4:-0} + 23 ))}
camera: {position: [0, 1, 6], look_at: [0, 0.5, 0], fov: 40}
lights: [{type: constant, radiance: 0.6}, {type: directional, direction: [-0.3, -1, -0.4], irradiance: 3}]
materials: [{name: red, type: diffuse, color: [0.7, 0.1, 0.1]}, {name: grey, type: diffuse, color: 0.5}]
objects:
  - {name: floor, shape: rectangle, width: 8, height: 8, material: grey, transform: {rotate: {euler: [-90, 0, 0]}}}
  - name: box
    shape: cube
    size: 0.6
    material: red
    motion:
      type: keyframes
      channels:
        translate:
          keys:
            - {time: 0, value: [-1.5, 0.3, 0]}
            - {time: 12, value: [0, 0.3, 0]}
            - {time: 23, value: [$3, 0.3, 0]}
YAML
}
R="--resolution 96x54 --spp 4 --no-progress"
echo "# 1. partial rerun never clobbers the cut"
shot shot.yaml shot 1.5
say $M render shot.yaml $R --deliver 24p,60i,contact
say $M render shot.yaml $R --overwrite --frames 20-23 --deliver 24p,60i,contact
TAILN=30 say ls out/shot/deliver 2>/dev/null || TAILN=30 say find out/shot -maxdepth 2 -name '*v00*'
echo "# 2. only what changed re-renders"
shot shot.yaml shot 2.5
say $M render shot.yaml $R
sed -i 's/name: box/name: crate/' shot.yaml
say $M render shot.yaml $R
echo "# 3. a shot's identity"
shot other.yaml shot 1.5
say $M render other.yaml $R --frames 0-1
echo "# 4. first: 1001 with keys in frames"
shot s1001.yaml shot1001 1.5 0
say $M render s1001.yaml $R --frames 0-23
shot s1001.yaml shot1001 1.5 1001
say $M validate s1001.yaml
say $M render s1001.yaml $R --deliver contact
say $M telecine out/shot1001 -o out/t1001.mp4
echo "# 7. small things"
say $M render shot.yaml -q $R
say $M render shot.yaml --dry-run $R
echo "workdir $w"
