"""The tools around the twin: simulate, estimate, evaluate, bench, plots and the ``nte-ref`` CLI.

They import the twin (``reference_py``'s top-level modules, numpy only) and may use any library
(csv, matplotlib, tqdm, filterpy…); the twin never imports them.
"""
