"""Host bench for the needle-force estimator CAN node.

- ``host_bench.dbc``: the node's DBC (firmware/can/nte.dbc) via cantools, with AUTOSAR E2E
  profile 11 protection via autosar-e2e and a configurable base id.
- ``host_bench.replay``: the engine that sends a scenario CSV as Depth/Force frames on a python-can bus
  (socketcan or slcan) at their timestamps and records the bus (CSV and candump log).
- ``host_bench/with-vcan``: runs a command with a real SocketCAN vcan0 (natively, or inside a
  user-mode-linux kernel when the host kernel has no CAN).
"""
