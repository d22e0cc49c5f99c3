"""``python -m solar_jax.bench physics|learner|train|startup|all [key=value ...]``:
throughput and compile time on this machine, printed as a table with the device and
package versions, a JSON file beside it.

- ``physics``: env steps/s of the suite's MJX step (random actions, no learning), MuJoCo C
  beside (``physics.py``);
- ``learner``: TD3 iterations/s and samples/s without physics, FLOP/s beside this
  machine's GEMM rate (``learner.py``);
- ``train``: rounds of ``train``: env steps/s, TD3 iterations/s, hours per 10M steps
  (``train.py``);
- ``startup``: seconds from ``python -m solar_jax.train`` to its first update, cold and
  warm compilation cache (``startup.py``);
- ``all``: the four in turn on one config, and a summary.

Every part takes ``train``'s keys (the run it measures: ``morph``, ``net``, ``num_envs``,
``td3.batch_size``, ``env.*``, ...) and its own (``--help`` lists them). Compilation is
always timed apart from running.
"""
