#!/bin/bash
# benchmarks/gpu.py on a lent accelerator machine, in one call of about 8 minutes (a lease
# is 15 minutes of device time, machine start included: this leaves time for one rerun):
# each part its own process under its own time limit (a part that ends keeps its JSON),
# everything written to $OUT, the log printed at the end, and the persistent compilation
# cache left in $OUT/cache for the next lease to carry in (SOLAR_JAX_CACHE: a warm start).
# That machine has JAX with CUDA but not MuJoCo: carry its wheels (Python 3.12, x86-64) in
# .whl/, fetched here with
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform any \
#     -d .whl mujoco==4.0.1 mujoco-core==4.0.1 mujoco-mjx==3.17.0 trimesh==5.2.0 glfw pyopengl
# Run: device run, carry [".whl"] (and a cache/ from an earlier lease to time a warm
# start), command "bash benchmarks/gpu_lease.sh", timeout 600 s.
out=${OUT:-benchmarks/results}
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site .whl/*.whl || exit 1
mkdir -p "$out/cache"
[ -d cache ] && cp -r cache/. "$out/cache/"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 SOLAR_JAX_CACHE=$out/cache
log=$out/gpu_lease.log
{
  nvidia-smi -L
  nproc
  python3 -c "import jax; from importlib.metadata import version as v; print(jax.devices(), \
[(p, v(p)) for p in ('jax', 'flax', 'optax', 'orbax-checkpoint', 'mujoco', 'mujoco-mjx', 'numpy')])"
} >>"$log" 2>&1
part() {
  local limit=$1
  shift
  echo "== $(date +%T) limit $limit s: $*" >>"$log"
  timeout "$limit" python3 -m benchmarks.gpu out="$out" "$@" >>"$log" 2>&1
  echo "== exit $? at $(date +%T)" >>"$log"
}
# In order of value. train: humanoid++'s cold start per program, then 1 warm-up and
# 2 timed rounds per update mode (the headline: hours per 10M steps); sweep: the paper's
# 4 seeds as lanes, with the device memory beside the predicted peak at 10M steps;
# physics: humanoid++ as one union program at 1, 64, 4,096 environments per robot beside
# MuJoCo C; learner: the update alone; physics_per_robot: humanoid++ as eight programs,
# against the union, last (what is left of the call).
part 200 parts=train
part 110 parts=sweep
part 90 parts=physics
part 60 parts=learner
part 90 parts=physics_per_robot
cat "$log"
