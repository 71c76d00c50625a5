"""The node's CAN bus as both sides of the project read and write it.

- ``reference_py.bus.dbc``: the DBC (firmware/can/nte.dbc) via cantools, with AUTOSAR E2E
  profile 11 protection via autosar-e2e and a configurable base id.
- ``reference_py.bus.candump``: a stream of frames written as a candump log.

The discrepancy workflow reads candump logs of measured trials with it, and the host bench
(``host_bench``) drives the node with it; it lives here, below both, so that the reference never
imports the bench that stands on it.
"""
