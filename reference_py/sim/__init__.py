"""Simulation of needle insertions: the ground truth every synthetic record is built from.

- ``reference_py.sim.motion``: the stage's motion -- LSPB moves (linear segments, parabolic
  blends), the phantom's insertion-dwell-retraction cycles and their duration.
- ``reference_py.sim.trajectory``: the estimator's test scenarios (insertion, dwell and
  retraction cycles sampled at a rate) from those moves.
- ``reference_py.sim.kernel``: one Kutta RK3 sub-step of the state equation as an affine map
  z -> a z + c (the simulator ``reference_py.sim.simulate`` and the workflow's fast simulator
  ``reference_py.discrepancy.fastsim`` both build on it).
- ``reference_py.sim.simulate``: the paper's force model along a trajectory, for batches of
  parameter sets in any working precision (the ground truth of ``nte-ref simulate``).
- The realistic phantom, one job per module: ``spec`` (what a phantom is made of), ``tissue`` (the
  tissue's force law along the stage motion), ``calibration`` (the measured statistics, the
  presets, the random ``lab`` tissue), ``phantom`` (one record: the sensor and the truth) and
  ``phantom_stats`` (a record's figures, summarised as the measured trials were).

It stands below the tools and the discrepancy workflow, which import it; it imports only the
twin's numeric modules (``fmath``), numpy and scipy.  The commands (``nte-ref simulate``,
``nte-ref phantom``) stay in ``reference_py/tools``.
"""
