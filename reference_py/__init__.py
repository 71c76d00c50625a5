"""Reference implementation of the needle-tissue force estimator (Asadian, Kermani, Patel 2012).

The numpy twin of the C library in ``firmware/``: same model, same RK3 step, same hand-derived
Jacobians, same EKF bank, same operation order — so both produce the same bits.
"""
__version__ = "0.1.0"
