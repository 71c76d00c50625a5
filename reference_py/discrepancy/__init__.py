"""Discrepancy workflow: find where the force model and measured insertions disagree,
name the physical effect that is missing, add it to the model and show how much the gap shrinks.

Entry points: :func:`reference_py.discrepancy.workflow.run` (library) and
``python -m reference_py.discrepancy.cli`` (command line).  The method is described in
``reference_py/discrepancy/DISCREPANCY.md``; the effect library is
:mod:`reference_py.discrepancy.effects`.
"""
