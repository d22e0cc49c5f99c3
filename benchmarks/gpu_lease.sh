#!/bin/bash
# benchmarks/gpu.py on a lent accelerator machine, in one call: each part its own process
# under its own time limit (a part that ends keeps its JSON), everything written to $OUT
# and the log printed at the end. That machine has JAX with CUDA but not MuJoCo: carry its
# wheels (Python 3.12, x86-64) in .whl/, fetched here with
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform any \
#     -d .whl mujoco==4.0.1 mujoco-core==4.0.1 mujoco-mjx==3.17.0 trimesh==5.2.0 glfw pyopengl
# (checked on CPU under that machine's jax 0.11.2: benchmarks/gpu.py size=tiny ran).
# Run: device run, carry [".whl"], command "bash benchmarks/gpu_lease.sh", timeout 600 s.
out=${OUT:-benchmarks/results}
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 SOLAR_JAX_CACHE=/tmp/solar_jax_cache
mkdir -p "$out"
log=$out/gpu_lease.log
{
  nvidia-smi -L
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
# The lease of 2026-12-04 (H200, jax 0.11.2) gave training 290 s, learner 165, throughput
# 95: the learner measured 2 of its 8 rows (compile 29-38 s each), the others none (the
# first humanoid++ round was not done after 290 s). Hence the training part alone, with
# the lease's whole time; it prints each phase as it ends (benchmarks/README.md).
part 560 parts=training # hours per 10M steps of humanoid++, the headline
cat "$log"
