"""pmsm_ev: physics of a sensorless PMSM electric-vehicle drive (Wicaksono, Harini,
Yusivar, "Sensorless PMSM Control using Fifth Order EKF in Electric Vehicle Application").

Modules: ``params`` (Tables I-II and chosen values), ``vehicle`` (eqs 1-9, 29),
``pmsm`` (10-13), ``transforms``, ``kernels`` (the per-step numerics, once), ``accel``
(compiling them), ``plant``, ``controller`` (14-20), ``observers`` (21-27, A1-A33),
``control_unit``, ``scenarios`` (section III), ``results`` (the result contract: the
columns, the angle error, eq 31's load torque, the energy bookkeeping; the figures of merit and
the bands that judge them are the application's, ``pmsm_cosim.app.metrics``). No FMI, no
files: the FMUs (``pmsm_ev_fmus``) and the co-simulation (``pmsm_cosim``; the monolithic reference
run is ``pmsm_cosim.app.reference``) build on it.
"""

__version__ = "0.1.0"
