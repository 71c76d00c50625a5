"""Host bench for the needle-force estimator CAN node.

- ``reference_py.bus``: the node's DBC (firmware/can/nte.dbc) with its E2E protection, and
  candump logs -- the bus layer the bench shares with the reference (the reference never
  imports the bench).
- ``host_bench.replay``: the engine that sends a scenario CSV as Depth/Force frames on a python-can bus
  (socketcan or slcan) at their timestamps and records the bus (CSV and candump log).
- ``host_bench/with-vcan``: runs a command with a real SocketCAN vcan0 (natively, or inside a
  user-mode-linux kernel when the host kernel has no CAN).
"""
