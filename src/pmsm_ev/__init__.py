"""pmsm_ev: physics of a sensorless PMSM electric-vehicle drive (Wicaksono, Harini,
Yusivar, "Sensorless PMSM Control using Fifth Order EKF in Electric Vehicle Application").

Modules: ``params`` (Tables I-II and chosen values), ``vehicle`` (eqs 1-9, 29),
``pmsm`` (10-13), ``transforms``, ``plant``, ``controller`` (14-20), ``observers``
(21-27, A1-A33), ``control_unit``, ``scenarios`` (section III), ``results``,
``reference`` (monolithic run).
"""

__version__ = "0.1.0"
