#!/bin/bash
# Existing zwidth tuner solvers, same budget (30 evaluations), one map-running process at a time.
cd "$(dirname "$0")" && mkdir -p runs && cd runs
run() { solver=$1; seed=$2
  s=$(date +%s.%N)
  nice -n 10 ../../target/release/zwidth tune --scene ../../examples/seed_2018.json --params '{"cutoff_hz":{"min":10,"max":499,"step":1}}' --objective k_width --max-evaluations 30 --solver $solver --seed $seed --accuracy draft --final-accuracy draft --finalists 1 --replicates 1 --json > tune_${solver}_$seed.json 2> tune_${solver}_$seed.err
  echo "$solver $seed rc=$? wall=$(echo "$(date +%s.%N) - $s" | bc)"
}
run auto 0; run nelder_mead 0; run golden 0; run particle_swarm 0; run particle_swarm 1; run particle_swarm 2
