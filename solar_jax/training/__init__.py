"""Training: the jitted round (``trainer``), its lanes for sweeps (``lanes``), the host loop
(``runner``), and what a run leaves on disk (``checkpoint``, ``logger``, ``rundir``).

It sits above the learner (``agent``, ``synergy``, ``networks``) and the data
(``replay``, ``env``, ``morphology``), and below the figures (``viz``) and the commands
(``train``, ``sweep``, ``rollout``, ``plot``).
"""
