#!/bin/bash
# Render every pool, one process at a time, 1 Cycles thread, into benchmarks/cache/pixel_releases/
# (<release>_<scene>_<pattern>.npy/.json); then analyse.py and extended.py (docs/findings/pixel_variance.md).
set -e
cd "$(dirname "$0")/../../.."  # the repository
POOLS=benchmarks/cache/pixel_releases; mkdir -p $POOLS/logs
export PYTHONPATH=$PWD
STUDY=benchmarks/studies/pixel_releases
N=${N:-300}
for scene in corner corner_glass; do
  for v in 4.5.4 5.1.2 5.2.3 5.3.0; do
    for p in TABULATED_SOBOL BLUE_NOISE AUTOMATIC; do
      f=$POOLS/${v}_${scene}_${p}.npy; [ -f $f ] && continue
      ~/.cache/welch-bias/bpy/$v/bin/python $STUDY/render_pool.py $scene $p $N $f > $POOLS/logs/${v}_${scene}_${p}.log 2>&1
      grep POOL $POOLS/logs/${v}_${scene}_${p}.log
    done
  done
  for p in SOBOL PROGRESSIVE_MULTI_JITTER; do
    f=$POOLS/3.4.1_${scene}_${p}.npy; [ -f $f ] && continue
    blender -b --factory-startup --python-exit-code 1 --python $STUDY/render_pool.py -- $scene $p $N $f > $POOLS/logs/3.4.1_${scene}_${p}.log 2>&1
    grep POOL $POOLS/logs/3.4.1_${scene}_${p}.log
  done
done
# control for bit-identity across processes: BLUE_NOISE and TABULATED_SOBOL again, 5 seeds, fresh process
for v in 4.5.4 5.1.2 5.2.3 5.3.0; do
  for p in BLUE_NOISE TABULATED_SOBOL; do
    f=$POOLS/repeat_${v}_corner_${p}.npy; [ -f $f ] && continue
    ~/.cache/welch-bias/bpy/$v/bin/python $STUDY/render_pool.py corner $p 5 $f > $POOLS/logs/repeat_${v}_${p}.log 2>&1
  done
done
