"""Slave of PassThroughPlant.fmu, for the step-cost benchmark (``pmsm-cosim bench``):
PmsmEvPlant's interface, parameters and FMI plumbing, but ``do_step`` computes nothing
(the outputs keep their initial values). It measures the floor of FMI calls plus
pythonfmu under the plant's interface (with the kernels compiled: of its compiled step, computing nothing;
``slave_support.PassThrough``)."""

from __future__ import annotations

from pmsm_ev_fmus.pmsm_ev_plant import PmsmEvPlant
from pmsm_ev_fmus.slave_support import PassThrough


class PassThroughPlant(PassThrough, PmsmEvPlant):
    """PmsmEvPlant without physics in the step."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = ("Benchmark unit: the interface of PmsmEvPlant; fmi2DoStep computes nothing, "
                            "the outputs keep their initial values.")
