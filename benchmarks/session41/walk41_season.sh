#!/bin/bash
# walk41's season: 12 sessions of the robocup4 rig (walk41_rig.py), seeds 65001-65012.
# Clocks: cam2 +3.1, cam3 -4.4, cam4 +2.2 ms (each day a little different), 0.4 px, 3 % misses.
# Broken on purpose: day3/m11 truncated (laptop died), day3/m12 a camera unplugged halfway
# (made by walk41_unplug.py), day2/m8 a second orange ball on the floor.
# usage: walk41_season.sh DIR   (DIR/rig.toml must exist)
set -e
D=$1; P="${PSLOG:-pslog}"
mkdir -p $D/season/day1 $D/season/day2 $D/season/day3
i=0
for day in 1 2 3; do
  for m in 1 2 3 4; do
    i=$((i+1)); seed=$((65000+i))
    o2=$(python3 -c "print(round(3.1+0.3*$day,2))"); o3=$(python3 -c "print(round(-4.4+0.2*$day,2))"); o4=$(python3 -c "print(round(2.2-0.4*$day,2))")
    extra=""
    [ $i = 8 ] && extra="--distractor 1.0,1.6,0.035"
    $P simulate --rig $D/rig.toml --motion rally --duration 6 --noise-px 0.4 --miss-rate 0.03 \
      --clock-offset cam2=$o2 --clock-offset cam3=$o3 --clock-offset cam4=$o4 --seed $seed $extra \
      -o $D/season/day$day/m$i.mcap
  done
done
