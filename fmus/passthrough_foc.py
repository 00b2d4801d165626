"""Slave of PassThroughFoc.fmu, for the step-cost benchmark (``pmsm-cosim bench``):
FocEkf5's interface, parameters and FMI plumbing, but ``do_step`` computes nothing (the
outputs keep their initial values). It measures the floor of FMI calls plus pythonfmu
under the controller's interface (with the kernels compiled: of its compiled step, computing nothing;
``slave_support.PassThrough``)."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave
from pmsm_ev_fmus.slave_support import PassThrough


class PassThroughFoc(PassThrough, FocSlave):
    """FocEkf5 without observer and controller in the step."""

    def __init__(self, **kwargs):
        super().__init__("ekf5", "no computation (benchmark unit)", **kwargs)
        self.description = ("Benchmark unit: the interface of FocEkf5; fmi2DoStep computes nothing, "
                            "the outputs keep their initial values.")
