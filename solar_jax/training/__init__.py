"""Training: the round as pure functions (``trainer``), one run or a sweep's runs as the
lanes of one program (``lanes``), its compiled programs (``programs``), the one host loop
for S lanes (``runner``), and what a run leaves on disk (``checkpoint``, ``logger``,
``rundir``).

It sits above the learner (``agent``, ``synergy``, ``networks``) and the data
(``replay``, ``env``, ``morphology``), and below the figures (``viz``) and the commands
(``train``, ``sweep``, ``rollout``, ``plot``).
"""
