"""The drive's application, on top of the engine and the sweeps: ``pmsm-cosim`` (``cli``), the
Python API (``api``), the drive's scenarios, FMUs and figures of merit (``drive``), its sweeps
(``studies``), figures (``figures``), the monolithic reference (``reference``), ``compare``,
``report`` and ``bench``; shipped scenarios in ``scenarios/``, sweeps in ``sweeps/``.
"""
